"""A replay pipeline ends when its nodes have processed what they received (bounded wait).

When ``bag_player`` has played the bag, the nodes may still hold scans in their queues (a
loaded machine, a high ``--rate``): stopping them at once threw those away (on a loaded
machine at 3x, 1,482 of 1,988 scans reached ekf_slam's output). :class:`DrainingManager`
(honcho's manager) therefore waits, when the player ended by itself, until the nodes'
``/diagnostics`` input status says every scan the bag has was handled: corner_extractor's
``processed`` plus ``dropped`` reach the bag's ``/scan`` count, ekf_slam received every
corner cloud the extractor published and has no feature set ``waiting`` (it processes the
last ones when the odometry ends, after its ``odometry_timeout``). The wait is bounded
(``--drain-timeout``); either way one line says what happened: everything processed, or how
many scans and sets were discarded when the nodes were stopped. A signal (Ctrl-C) stops at
once, as before.

At the start, the player is started only once the nodes run and ekf_slam's
``corners/features`` subscription is matched with the corner extractor (``matched.*`` on
``/diagnostics``; at most ``READY_TIMEOUT_S``): the player already waits for the subscribers
of its own topics, but the first corner clouds went out before that match, and their
feature sets went on without them (the trajectory then differed from the offline one);
and, with ``also_ready`` (the replay's ``/pose`` recorder), until that holds too.
"""

import multiprocessing
import threading
import time
from typing import Callable, Dict, Optional, Tuple

from honcho.manager import KILL_WAIT, Manager

#: Seconds the replay waits for its nodes to start and connect before starting the player.
READY_TIMEOUT_S = 60.0


def scans_in_bag(bag: str) -> Optional[int]:
    """Return the number of ``/scan`` messages in a bag (None when it cannot be read)."""
    from landmark_nav.bag import BagReader
    try:
        with BagReader(bag) as reader:
            info = reader.topics().get('/scan')
    except Exception:  # noqa: B902 - the player has named the problem with the bag
        return None
    return None if info is None else int(info.count)


def drained(status: Dict[str, Dict[str, str]], scans: int) -> Optional[str]:
    """Return what is still unprocessed by the replay nodes, or None when nothing is.

    Args:
        status: The latest ``/diagnostics`` input values by node name (``corner_extractor``,
            ``ekf_slam``).
        scans: The bag's ``/scan`` messages (all published by the player).
    """
    ce, ek = status.get('corner_extractor'), status.get('ekf_slam')
    if ce is None or ek is None:
        return 'no input status from ' + ' and '.join(
            n for n, v in (('corner_extractor', ce), ('ekf_slam', ek)) if v is None)
    handled = int(ce.get('processed', 0)) + int(ce.get('dropped', 0))
    sets = int(ce.get('processed', 0))
    received, waiting = int(ek.get('received.corners', 0)), int(ek.get('waiting', 0))
    lost = sum(int(ek.get(f'{k}.corners/features', 0)) for k in ('lost', 'before_match'))
    missing = []
    if handled < scans:
        missing.append(f'corner_extractor handled {handled} of {scans} scans')
    if received + lost < sets:
        missing.append(f'ekf_slam received {received} of {sets} corner sets ({lost} lost)')
    if waiting:
        missing.append(f'ekf_slam has {waiting} feature sets waiting')
    return '; '.join(missing) or None


def summary(status: Dict[str, Dict[str, str]]) -> str:
    """Return each node's processed and dropped counts (with the reasons), one line."""
    parts = []
    for name, values in sorted(status.items()):
        reasons = ', '.join(f'{k[8:]} {v}' for k, v in sorted(values.items())
                            if k.startswith('dropped.'))
        parts.append(f'{name} processed {values.get("processed", "?")}, dropped '
                     f'{values.get("dropped", "?")}' + (f' ({reasons})' if reasons else ''))
    return '; '.join(parts)


def watch_inputs(until: Callable[[Dict[str, Dict[str, str]]], bool], timeout_s: float
                 ) -> Tuple[bool, Dict[str, Dict[str, str]], float]:
    """Watch the nodes' ``/diagnostics`` input status until ``until(status)`` or a timeout.

    Returns:
        ``(held, the latest values by node name, seconds waited)``.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('pipeline_watch', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    latest: Dict[str, Dict[str, str]] = {}

    def on_status(msg: DiagnosticArray) -> None:
        for s in msg.status:
            name, _, kind = s.name.partition(': ')
            if kind == 'input':
                latest[name] = {kv.key: kv.value for kv in s.values}

    node.create_subscription(DiagnosticArray, '/diagnostics', on_status, 100)
    start = time.monotonic()
    try:
        while time.monotonic() - start < timeout_s:
            executor.spin_once(timeout_sec=0.2)
            if until(latest):
                return True, latest, time.monotonic() - start
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return False, latest, time.monotonic() - start


def ready(status: Dict[str, Dict[str, str]]) -> bool:
    """Whether the replay nodes run and ekf_slam is matched with the corner extractor."""
    ek = status.get('ekf_slam', {})
    return 'corner_extractor' in status and int(ek.get('matched.corners/features', 0)) > 0


def wait_until_drained(scans: int, timeout_s: float, say: Callable[[str], None]) -> bool:
    """Watch ``/diagnostics`` until :func:`drained` holds or ``timeout_s`` passes; say which.

    Returns:
        True when every scan was processed (or dropped with a reason) by the nodes.
    """
    done, latest, waited = watch_inputs(lambda s: drained(s, scans) is None, timeout_s)
    if done:
        say(f'replay drained: the nodes handled all {scans} scans of the bag '
            f'({waited:.1f} s after the player ended): ' + summary(latest))
    else:
        say(f'replay not drained after {timeout_s:g} s, stopping the nodes: '
            f'{drained(latest, scans)} (the rest is discarded); {summary(latest)}')
    return done


class DrainingManager(Manager):
    """honcho's manager that lets the replay nodes drain when the player ends by itself.

    Args:
        printer: honcho's printer.
        scans: The bag's ``/scan`` count (None: no wait).
        timeout_s: Largest wait [s].
    """

    def __init__(self, printer, scans: Optional[int], timeout_s: float) -> None:
        """Set up the wait (started when the player stops)."""
        super().__init__(printer)
        self.scans = scans
        self.timeout_s = float(timeout_s)
        self.drained: Optional[bool] = None
        self.player_started: Optional[float] = None  # monotonic [s]
        self.player_ended: Optional[float] = None  # monotonic [s], when it ended by itself
        self._draining = False
        #: Also waited for before the player starts (e.g. the pose recorder's match).
        self.also_ready: Callable[[], bool] = lambda: True
        self._term_at: Optional[float] = None
        self._guard = threading.Lock()

    def _start(self) -> None:
        """Start the nodes; the player once they are up and connected (bounded wait).

        The player already waits for its topics' subscribers; this also waits until ekf_slam
        is matched with the corner extractor's ``corners/features`` (else the first corner
        clouds went out before the match, and their feature sets on without them).
        """
        if self.scans is None or 'bag_player' not in self._processes:
            super()._start()
            return
        player = self._processes.pop('bag_player')
        super()._start()
        ok, _, waited = watch_inputs(lambda status: ready(status) and self.also_ready(),
                                     READY_TIMEOUT_S)
        self._system_print(f'replay nodes {"ready" if ok else "not ready"} after '
                           f'{waited:.1f} s: starting bag_player\n')
        self._processes['bag_player'] = player
        player['process'] = multiprocessing.Process(name='bag_player',
                                                    target=player['obj'].run,
                                                    args=(self.events, True))
        player['process'].start()
        self.player_started = time.monotonic()

    def terminate(self) -> None:
        """Stop the nodes: after the drain when the player ended with 0, else at once."""
        player = self._processes.get('bag_player', {})
        if player.get('returncode') == 0 and self.player_ended is None:
            self.player_ended = time.monotonic()
        with self._guard:
            if (self._draining or self.scans is None or self.returncode != 0
                    or player.get('returncode') != 0 or self.timeout_s <= 0.0):
                self._stop_now()
                return
            self._draining = True
        threading.Thread(target=self._drain_then_stop, daemon=True).start()

    def _drain_then_stop(self) -> None:
        self.drained = wait_until_drained(self.scans, self.timeout_s, self._system_print_line)
        with self._guard:
            self._stop_now()

    def _system_print_line(self, text: str) -> None:
        self._system_print(text + '\n')

    def _stop_now(self) -> None:
        if self._term_at is None:
            self._term_at = time.monotonic()
        Manager.terminate(self)

    def played_seconds(self) -> Optional[float]:
        """Seconds the player took to play the bag (None: it did not end by itself)."""
        if self.player_started is None or self.player_ended is None:
            return None
        return self.player_ended - self.player_started

    def kill(self) -> None:
        """SIGKILL only ``KILL_WAIT`` seconds after the SIGTERM (not during the drain)."""
        if self._term_at is not None and time.monotonic() - self._term_at > KILL_WAIT:
            super().kill()


__all__ = ['drained', 'DrainingManager', 'ready', 'READY_TIMEOUT_S', 'scans_in_bag',
           'summary', 'wait_until_drained', 'watch_inputs']
