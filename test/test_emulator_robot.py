"""``emulate robot``: the laser scans from wherever the P2OS commands drove the base.

The devices are driven directly with a manual clock (bytes in, frames out): the base gets
P2OS commands, the laser a continuous scan request; every scan the laser sent must equal
a noise-free ray cast from the base's true path at the beam times, as the base recorded it
by the end of the run (so the poses the laser predicted past the base's last cycle are
checked against what the base then did).
"""

import io
import math

from landmark_nav.drivers import p2os
from landmark_nav.emulators.laser_scene import SceneConfig
from landmark_nav.emulators.robot import make_robot, RobotBase, TruthWriter
from landmark_nav.emulators.urg import URG_04LX
from landmark_nav.evaluation.trajectory import read_tum
from landmark_nav.geometry import relative
from landmark_nav.sim.laser import compose
from landmark_nav.sim.robot import step_pose
import numpy as np
import pytest

cmd = p2os.encode_command
QUIET = SceneConfig(sigma_range=0.0, sigma_angle=0.0, p_dropout=0.0, p_spurious=0.0,
                    p_error=0.0, p_close=0.0)
MOUNT = (0.12, -0.03, 0.05)


def _open(base: RobotBase, now: float) -> None:
    for name in ('SYNC0', 'SYNC1', 'SYNC2', 'OPEN'):
        base.receive(cmd(name), now)
    base.receive(cmd('ENABLE', 1), now)


def _drive(laser_model, laser_first: bool, commands, seconds: float, step: float = 0.002,
           base_every: int = 1, rate: float = 1.0):
    base, laser = make_robot('urg', laser_model, MOUNT, QUIET, {'baud': 0}, rate=rate,
                             start_pose=(1.2, 1.2, 0.0), sonar_noise=False)
    truth = io.StringIO()
    base.listeners.append(TruthWriter(truth, origin=(1.2, 1.2, 0.0), wall_offset=100.0,
                                      cycle=base.cycle_s, period=min(0.01, base.cycle_s)))
    _open(base, 0.0)
    laser.receive(b'MD0000108001000\n' if laser_model != 'urg-04lx'
                  else b'MD0044072501000\n', 0.0)
    pending = sorted(commands)
    n = int(round(seconds / step))
    for i in range(1, n + 1):
        now = i * step
        while pending and pending[0][0] <= now:
            _, name, value = pending.pop(0)
            base.receive(cmd(name, value), now)
        for device in ((laser, base) if laser_first else (base, laser)):
            if device is laser or i % base_every == 0:
                device.poll(now)
    return base, laser, truth


COMMANDS = [(0.3, 'VEL', 250), (0.3, 'RVEL', 0), (1.0, 'RVEL', 25), (1.45, 'RVEL', -40),
            (1.9, 'VEL', 100), (2.2, 'RVEL', 0), (2.5, 'PULSE', None), (2.8, 'STOP', None)]


@pytest.mark.parametrize('model,laser_first,base_every,rate', [
    ('utm-30lx', True, 1, 1.0), ('utm-30lx', False, 1, 1.0), ('urg-04lx', True, 1, 1.0),
    ('utm-30lx', True, 150, 1.0),  # the base's thread polled every 0.3 s only (a loaded host)
    ('utm-30lx', False, 1, 10.0)])  # the load test's data rates: 400 scans/s, 10 ms cycles
def test_every_scan_is_cast_from_the_bases_true_path(model, laser_first, base_every, rate):
    base, laser, _ = _drive(model, laser_first, COMMANDS, 3.0, base_every=base_every,
                            rate=rate)
    sent = list(laser.sent)
    assert len(sent) >= min(laser.sent.maxlen, rate * (110 if model == 'utm-30lx' else 28))
    assert base.predicted_queries > 0  # some beams lay past the base's last cycle
    p = laser.params
    steps = np.arange(sent[0].start_step, sent[0].end_step + 1)
    angles = (steps - p.afrt) * (2.0 * math.pi / p.ares)
    worst, moved = 0.0, 0.0
    start = np.array([1.2, 1.2, 0.0])
    for scan in sent:
        beam_t = scan.step0_time + steps * laser.step_time
        poses = compose(base.pose_at(beam_t), MOUNT)
        moved = max(moved, float(np.hypot(*(poses[-1, :2] - start[:2]))))
        hit = laser.scene.world.raycast(poses[:, :2], poses[:, 2] + angles, p.dmax_mm / 1e3)
        r = hit.ranges
        ok = np.isfinite(r) & np.isfinite(scan.expected) & (r > p.dmin_mm / 1e3)
        assert ok.mean() > 0.5  # the URG-04LX reaches 5.6 m only
        worst = max(worst, float(np.max(np.abs(scan.expected[ok] - r[ok]))))
    assert worst <= 0.0005 + 1e-6  # whole millimetres of the protocol
    assert moved > 0.5  # the laser really rode on the moving base


def test_pose_inside_a_cycle_follows_eqs_1_to_5_and_ends_on_the_reported_pose():
    base, _, _ = _drive('utm-30lx', True, COMMANDS, 2.0)
    t_end, start, v, w = base._path[-5]
    mid = base.pose_at(t_end - 0.04)
    assert mid == pytest.approx(step_pose(start, v, w, 0.06), abs=1e-12)
    nxt = base._path[-4]
    assert base.pose_at(t_end) == pytest.approx(nxt[1], abs=1e-12)
    assert abs(v) > 0.1 and abs(w) > 0.1


def test_cycles_run_for_the_laser_are_sent_by_the_base():
    base, laser = make_robot('urg', 'utm-30lx', MOUNT, QUIET, {'baud': 0})
    _open(base, 0.0)
    base.poll(0.0)
    base.receive(cmd('VEL', 200), 0.05)
    laser.receive(b'MD0000108001000\n', 0.05)
    for i in range(1, 5):  # 0.8 s of laser polls, none of the base
        laser.poll(0.05 + 0.2 * i)
    assert len(base._path) >= 7  # the laser ran the base's cycles
    base.pose_at(np.array([1.4]))  # a laser thread 0.5 s late asks at once
    assert len(base._path) >= 13
    frames = base.poll(1.45)
    decoder = p2os.P2osDecoder()
    sips = [f for frame in frames for f in decoder.feed(frame)]
    assert len(sips) == len(base.sent) >= 14  # every cycle's packet goes out, once
    assert base.poll(1.45) == []


def test_truth_file_is_the_true_path_in_the_start_frame():
    base, _, truth = _drive('utm-30lx', False, COMMANDS, 3.0)
    path = io.StringIO(truth.getvalue())
    lines = [row for row in path.read().splitlines() if not row.startswith('#')]
    stamps = np.array([float(row.split()[0]) for row in lines])
    assert np.allclose(np.diff(stamps), 0.01, atol=1e-6)
    tmp = np.array([[float(v) for v in row.split()[1:]] for row in lines])
    t = stamps - 100.0
    world = base.pose_at(t)
    expected = relative(np.array([1.2, 1.2, 0.0]), world)
    assert tmp[:, :2] == pytest.approx(expected[:, :2], abs=2e-6)
    yaw = 2.0 * np.arctan2(tmp[:, 5], tmp[:, 6])
    assert np.abs(np.angle(np.exp(1j * (yaw - expected[:, 2])))).max() < 1e-6


def test_truth_file_reads_as_tum(tmp_path):
    _, _, truth = _drive('utm-30lx', False, COMMANDS[:2], 1.0)
    f = tmp_path / 'truth.tum'
    f.write_text(truth.getvalue())
    traj = read_tum(f)
    assert len(traj.stamps_ns) > 50


def test_bad_robot_options_are_clear_errors():
    with pytest.raises(ValueError, match='laser must be one of'):
        make_robot('sick')
    with pytest.raises(ValueError, match='URG model'):
        make_robot('urg', 'utm-99')
    with pytest.raises(ValueError, match='laser mount'):
        make_robot('urg', mount=(0.0, math.nan, 0.0))
    assert URG_04LX.params.model == 'URG-04LX'
    for rate in (0.0, math.inf):
        with pytest.raises(ValueError, match='rate must be in'):
            make_robot('urg', rate=rate)
    with pytest.raises(ValueError, match='1 for the lms200'):
        make_robot('lms200', rate=10.0)


def test_rate_multiplies_the_data_rates_not_the_motion():
    """--rate 10 (the soak's 10x): 400 scans/s and 100 status packets/s, same motion."""
    runs = {rate: _drive('utm-30lx', False, COMMANDS, 3.0, rate=rate) for rate in (1.0, 10.0)}
    (base1, laser1, _), (base10, laser10, _) = runs[1.0], runs[10.0]
    assert (laser1.period, laser10.period) == pytest.approx((0.025, 0.0025), rel=1e-9)
    assert (base1.cycle_s, base10.cycle_s) == (0.1, 0.01)
    assert len(base10.sent) == pytest.approx(10 * len(base1.sent), abs=10)
    for laser, hz in ((laser1, 40.0), (laser10, 400.0)):  # the last 400 scans are kept
        span = laser.sent[-1].step0_time - laser.sent[0].step0_time
        assert (len(laser.sent) - 1) / span == pytest.approx(hz, rel=1e-6)
        assert laser.sent[-1].step0_time > 2.95  # scanning to the end
    t = np.linspace(0.2, 2.9, 28)  # the commands act one cycle (100 or 10 ms) later
    lag = np.abs(base10.pose_at(t)[:, :2] - base1.pose_at(t)[:, :2]).max()
    assert 0.0 < lag < 0.09 * 0.25  # at most the 90 ms earlier response at 0.25 m/s (11 mm)


def test_scans_and_status_packets_a_late_host_loses_are_counted():
    """At 10x a busy host polls the emulator late: what it cannot send is counted, not lost."""
    base, laser = make_robot('urg', 'utm-30lx', MOUNT, QUIET, {'baud': 0}, rate=10.0)
    _open(base, 0.0)
    base.poll(0.0)
    laser.receive(b'MD0000108001000\n', 0.0)
    for i in range(1, 51):
        laser.poll(0.002 * i)
    sent = laser.scans_sent
    assert sent >= 38 and laser.scans_skipped == 0  # 2.5 ms scans ready by 0.1 s
    laser.poll(0.2)  # polled 100 ms late: 40 periods passed, the last ones cast
    assert laser.scans_skipped + laser.scans_sent - sent == 40 and laser.scans_skipped >= 35
    base, _ = make_robot('urg', rate=10.0)
    _open(base, 0.0)
    base.poll(0.0)
    frames = base.poll(0.1)  # its thread 100 ms late: 10 cycles, all sent (late)
    assert (len(frames), base.packets_not_sent) == (10, 0)
    frames = base.poll(0.405)  # 300 ms late: those of the last 150 ms go out
    assert (len(frames), base.packets_not_sent) == (15, 15) and base.seq == 40


def test_the_base_records_are_bounded_on_a_long_run():
    """The base keeps the last ``record_s`` seconds of its records (60 s by default).

    The live emulator grew 3.2 MB a minute: every status packet (with its sonar values,
    about 5 kB) and every command was kept. Once the records are full, further cycles leave
    no more of them alive.
    """
    import gc

    from landmark_nav.emulators.p2os import ReceivedCommand, SentStatus
    assert make_robot('urg')[0].sent.size == 600  # 60 s of 10 Hz cycles
    base, _ = make_robot('urg', start_pose=(1.2, 1.2, 0.0), record_s=10.0)
    _open(base, 0.0)
    t = 0.0

    def alive_after(n):
        """Run ``n`` cycles turning on the spot; return the live records of each kind."""
        nonlocal t
        for _ in range(n):
            t += base.cycle_s
            for c in (cmd('VEL', 0), cmd('RVEL', 20), cmd('PULSE')):
                base.receive(c, t)
            base.poll(t)
        gc.collect()
        objects = gc.get_objects()
        return (sum(isinstance(o, SentStatus) for o in objects),
                sum(isinstance(o, ReceivedCommand) for o in objects), len(base._path))

    assert alive_after(300) == (100, 400, 300)
    assert alive_after(600) == (100, 400, 600)  # one minute more: the true path's 60 s
    assert alive_after(600) == (100, 400, 600)


def test_the_command_keeps_records_of_a_few_seconds():
    """``emulate robot`` kept a minute of records nobody reads (growing after the warm-up)."""
    from landmark_nav.emulators import robot
    from landmark_nav.tools.cli import build_parser
    base, laser = robot.make_from_args(build_parser().parse_args(['emulate', 'robot']))
    assert base.sent.size == round(robot.CLI_RECORD_S / base.cycle_s) == 20
    assert base.commands.size == 4 * base.sent.size
    assert laser.sent.maxlen == robot.CLI_RECORD_SCANS
