"""``landmark_nav emulate urg|lms200|p2os|robot``: serve emulated devices on a pty and TCP.

Each emulator module (``landmark_nav.emulators.<name>``) provides ``add_arguments(parser)``
for its own options and ``make_device(args) -> Device``; this module adds the common
options (endpoints, faults) and runs :func:`~landmark_nav.emulators.server.serve_forever`.
A module serving several devices (``robot``: the base and its laser) provides
``serve(args, announce)`` instead.
"""

import argparse
import importlib
import threading
import time
from typing import List, Tuple

from landmark_nav.emulators.server import DeviceServer, Fault, FaultInjector, parse_fault

EMULATORS = {
    'urg': ('landmark_nav.emulators.urg', 'Hokuyo URG/UTM laser speaking SCIP 2.0'),
    'lms200': ('landmark_nav.emulators.lms200', 'SICK LMS200/291 laser (LMS2xx telegrams)'),
    'p2os': ('landmark_nav.emulators.p2os', 'Pioneer base speaking P2OS (odometry, sonars)'),
    'robot': ('landmark_nav.emulators.robot', 'one robot: the P2OS base and a laser (urg or '
              'lms200) on it, the laser scanning from wherever cmd_vel drove the base'),
}


def _scheduled_fault(text: str) -> Tuple[float, Fault]:
    """Parse ``KIND[:SECONDS]@AT`` (e.g. ``vanish:2@10``: the port disappears 10 s in)."""
    spec, sep, at = text.partition('@')
    try:
        fault = parse_fault(spec)
        start = float(at) if sep else 0.0
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    if start < 0.0:
        raise argparse.ArgumentTypeError(f'fault time must be >= 0 s, got {start}')
    return start, fault


def add_parsers(sub: argparse._SubParsersAction, parser_class: type) -> None:
    """Add the ``emulate`` subcommand with one sub-subcommand per device."""
    p = sub.add_parser('emulate', help='serve an emulated laser or robot base on a pty / TCP '
                                       'port, driven by the simulator world')
    devices = p.add_subparsers(dest='device', required=True, metavar='DEVICE',
                               parser_class=parser_class)
    for name, (module, help_text) in EMULATORS.items():
        d = devices.add_parser(name, help=help_text)
        link = 'p2os' if name == 'robot' else name  # the robot's --link is its base's
        d.add_argument('--link', default=f'/tmp/landmark_nav_{link}',
                       help=f'symlink to the pseudo-terminal (default /tmp/landmark_nav_{link}; '
                            '"" for no pty)')
        d.add_argument('--tcp', type=int, default=None, metavar='PORT',
                       help='also listen on this TCP port (0: any free port); p2os and '
                            "robot listen on MobileSim's 8101 unless given")
        d.add_argument('--tcp-host', default='127.0.0.1', help='address to bind')
        d.add_argument('--seed', type=int, default=1, help='random seed (noise, faults)')
        d.add_argument('--fault-rate', type=float, default=0.0,
                       help='probability per frame of a random frame fault (garbage, '
                            'corrupt, truncate, drop)')
        d.add_argument('--fault', type=_scheduled_fault, action='append', default=[],
                       metavar='KIND[:S]@T',
                       help='inject a fault T seconds after start: garbage, corrupt, truncate, '
                            'drop, silence:S or vanish:S (repeatable)')
        importlib.import_module(module).add_arguments(d)
        d.set_defaults(func=run)


def _schedule(server: DeviceServer, faults: List[Tuple[float, Fault]]) -> None:
    start = time.monotonic()
    for at, fault in sorted(faults, key=lambda item: item[0]):
        time.sleep(max(0.0, start + at - time.monotonic()))
        print(f'injecting {fault.kind} ({fault.duration:g} s)', flush=True)
        server.inject(fault)


def run(args: argparse.Namespace) -> int:
    """Build the device and serve it until Ctrl-C."""
    from landmark_nav.emulators.server import serve_forever
    module = importlib.import_module(EMULATORS[args.device][0])
    if hasattr(module, 'serve'):  # several devices (robot): the module serves them
        return module.serve(args, announce=lambda text: print(text, flush=True))
    device = module.make_device(args)
    server = DeviceServer(device, link=args.link or None, tcp_port=args.tcp,
                          tcp_host=args.tcp_host,
                          faults=FaultInjector(seed=args.seed, rate=args.fault_rate))
    if args.fault:
        threading.Thread(target=_schedule, args=(server, args.fault), daemon=True).start()
    serve_forever(server, announce=lambda text: print(text, flush=True))
    return 0
