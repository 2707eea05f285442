"""Hypothesis strategies shared by the protocol fuzz tests: mutated frames, random chunking."""

from typing import Callable, List, Sequence

from hypothesis import strategies as st


@st.composite
def mutated(draw, pool: Sequence[bytes], special: Sequence[int],
            fix: Callable[[bytearray], bytearray]):
    """Draw a valid frame of ``pool`` with up to 4 flips, truncations, insertions, deletions.

    One draw in ten is plain random bytes instead. ``special`` are byte values worth
    writing into a frame (framing characters); ``fix`` recomputes the frame's length and
    checksum fields where it can (returning the data unchanged otherwise), so that mutated
    frames also reach the parsers behind the checksum test.
    """
    data = bytearray(draw(st.sampled_from(pool)))
    if draw(st.integers(0, 9)) == 0:
        return bytes(draw(st.binary(max_size=200)))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(['flip', 'truncate', 'insert', 'delete', 'byte', 'fix']))
        pos = draw(st.integers(0, len(data)))
        if op == 'flip' and pos < len(data):
            data[pos] ^= 1 << draw(st.integers(0, 7))
        elif op == 'byte' and pos < len(data):
            data[pos] = draw(st.sampled_from(special))
        elif op == 'truncate':
            del data[pos:]
        elif op == 'insert':
            data[pos:pos] = draw(st.binary(min_size=1, max_size=8))
        elif op == 'delete':
            del data[pos:pos + draw(st.integers(1, 8))]
        elif op == 'fix':
            data = fix(data)
    return bytes(data)


#: frames per Hypothesis example in the 10,000-frame fuzz tests: 1,000 examples of 10 frames
#: each cost half the time of 10,000 examples of one (Hypothesis's own work per example),
#: and a failing batch still shrinks to its one offending frame
FRAMES_PER_EXAMPLE = 10


def frame_batches(frames):
    """Draw lists of exactly ``FRAMES_PER_EXAMPLE`` values of the strategy ``frames``."""
    return st.lists(frames, min_size=FRAMES_PER_EXAMPLE, max_size=FRAMES_PER_EXAMPLE)


def random_chunks(stream: bytes, rnd, cuts: int = 5) -> List[bytes]:
    """Cut ``stream`` at up to ``cuts`` random places (``rnd``: a Hypothesis random)."""
    at = sorted(rnd.sample(range(len(stream) + 1), min(cuts, len(stream))))
    return [stream[a:b] for a, b in zip([0] + at, at + [len(stream)])]
