"""Describe a bag: topics, types, counts, duration and size."""

from pathlib import Path

from landmark_nav.bag import BagReader


def bag_size_bytes(path) -> int:
    """Return the total size of the files of a bag directory (or file)."""
    path = Path(path)
    if path.is_file():
        return path.stat().st_size
    return sum(f.stat().st_size for f in path.rglob('*') if f.is_file())


def describe_bag(path) -> str:
    """Return a short human-readable description of a bag."""
    with BagReader(path) as reader:
        topics = reader.topics()
        duration = reader.duration_ns / 1e9
    lines = [f'bag: {path}', f'duration: {duration:.1f} s',
             f'size: {bag_size_bytes(path) / 1e6:.2f} MB', 'topics:']
    for name, info in sorted(topics.items()):
        rate = info.count / duration if duration > 0 else 0.0
        latched = ' (latched)' if info.latched else ''
        lines.append(f'  {name}  {info.type_name}  {info.count} msgs  {rate:.1f} Hz{latched}')
    return '\n'.join(lines)
