"""Laser emulators (URG SCIP 2.0, SICK LMS200) driven with a simulated clock, no ports."""

import math
import struct

from landmark_nav.drivers import lms2xx, scip2
from landmark_nav.emulators.laser_scene import LaserScene, SceneConfig
from landmark_nav.emulators.lms200 import LmsDevice, range_limits
from landmark_nav.emulators.urg import URG_04LX, UrgDevice, UTM_30LX
from landmark_nav.tools.cli import build_parser
import numpy as np
import pytest

WRAP = 1 << 24


class Wire:
    """Drive a device with a simulated clock; collect its bytes and decode them."""

    def __init__(self, device, decoder, t0=100.0, step=0.001):
        self.device, self.decoder = device, decoder
        self.t, self.step = t0, step
        self.log = []  # (time, bytes) of every delivery

    def run(self, seconds, send=b''):
        out = []
        if send:
            out += self._take(self.device.receive(send, self.t))
        for _ in range(int(round(seconds / self.step))):
            self.t += self.step
            out += self._take(self.device.poll(self.t))
        return out

    def _take(self, frames):
        data = b''.join(frames)
        if data:
            self.log.append((self.t, data))
        return list(self.decoder.feed(data)) if data else []

    def raw(self, seconds, send=b''):
        """Return the bytes delivered (not decoded)."""
        start = len(self.log)
        self.run(seconds, send)
        return b''.join(d for _, d in self.log[start:])


def urg(model=UTM_30LX, **kwargs):
    return Wire(UrgDevice(model, **kwargs), scip2.Scip2Decoder())


def lms(**kwargs):
    return Wire(LmsDevice(**kwargs), lms2xx.Lms2xxDecoder())


def _frames(items, cls):
    return [i for i in items if isinstance(i, cls)]


# ---------------------------------------------------------------------------- URG


@pytest.mark.parametrize('model,steps,fov_deg,period', [
    (UTM_30LX, 1081, 270.0, 0.025), (URG_04LX, 682, 239.41, 0.1)])
def test_pp_describes_the_model_geometry(model, steps, fov_deg, period):
    w = urg(model)
    reply, = w.run(0.3, b'PP\n')  # 0.11 s at the URG-04LX's 19200 baud
    p = scip2.SensorParams.from_info(reply)
    assert p.amax - p.amin + 1 == steps
    assert math.degrees(p.step_angle(p.amax) - p.step_angle(p.amin)) == \
        pytest.approx(fov_deg, abs=0.01)
    assert 60.0 / p.scan_rpm == pytest.approx(period)
    assert reply.checksum_warnings == ()


def test_identity_status_and_laser_commands():
    w = urg()
    vv, = w.run(0.01, b'VV\n')
    assert vv.as_dict()['PROT'] == 'SCIP 2.0' and 'UTM-30LX' in vv.as_dict()['PROD']
    ii, = w.run(0.01, b'II\n')
    assert ii.as_dict()['STAT'] == 'Sensor works well.' and ii.as_dict()['LASR'] == 'OFF'
    gd, = w.run(0.01, b'GD0000108001\n')
    assert (gd.command, gd.status) == ('GD', '10')  # laser off
    assert [r.status for r in w.run(0.01, b'BM\n') + w.run(0.01, b'BM\n')] == ['00', '02']
    assert w.run(0.01, b'II\n')[0].as_dict()['LASR'] == 'ON'
    qt, = w.run(0.01, b'QT;tag1\n')
    assert (qt.command, qt.status, qt.tag) == ('QT', '00', 'tag1')


def test_errors_for_unknown_commands_and_bad_parameters():
    w = urg()
    assert w.raw(0.01, b'XY\n') == b'XY\n0Dd\n\n'  # unknown command, checksum of '0D'
    assert w.raw(0.01, b'MD0000\n') == b'MD0000\n0Cc\n\n'  # parameters missing
    assert w.raw(0.01, b'QT;' + b'x' * 17 + b'\n').split(b'\n')[1] == b'0Gg'
    # the host decoder reports the unknown echoes above as skipped bytes, then decodes
    reply = _frames(w.run(0.01, b'MD0100005001000\n'), scip2.StatusReply)[0]
    assert reply.status == '05'  # end before start
    assert w.run(0.01, b'MD0000200001000\n')[0].status == '04'  # end beyond the last step
    assert w.raw(0.01, b'MD00001080AB000\n').split(b'\n')[1][:2] == b'03'
    assert urg(URG_04LX).run(0.1, b'ME0044072501000\n')[0].status == '0D'  # no intensities


def test_scip1_boot_needs_the_switch():
    w = urg(URG_04LX, scip1_boot=True)
    qt, = w.run(0.1, b'QT\n')
    assert qt.status == 'E'
    sw, = w.run(0.1, b'SCIP2.0\n')
    assert (sw.command, sw.status) == ('SCIP2.0', '0')
    assert w.run(0.1, b'QT\n')[0].status == '00'


def test_time_adjust_mode_and_the_24_bit_wrap():
    w = urg(clock_start_ms=WRAP - 50)
    assert w.run(0.01, b'TM1\n')[0].status == '04'  # not in time-adjust mode
    assert w.run(0.01, b'TM0\n')[0].status == '00'
    assert w.run(0.01, b'QT\n')[0].status == '0E'  # other commands refused in TM mode
    t1, = w.run(0.01, b'TM1\n')
    w.run(0.09)
    t2, = w.run(0.01, b'TM1\n')
    assert t1.timestamp_ms >= WRAP - 50 and t2.timestamp_ms < 100  # wrapped
    assert (t2.timestamp_ms - t1.timestamp_ms) % WRAP == pytest.approx(100, abs=2)
    assert w.run(0.01, b'TM2\n')[0].status == '00'
    assert w.run(0.01, b'TM2\n')[0].status == '03'
    w.run(0.01, b'RS\n')
    assert w.run(0.01, b'TM0\n')[0].status == '00'
    assert w.run(0.0, b'TM1\n')[0].timestamp_ms < 30  # RS reset the counter


def test_md_stream_timing_geometry_and_rep117_values():
    w = urg(clock_start_ms=WRAP - 60)
    items = w.run(0.3, b'MD0000108001000\n')
    ack, *scans = items
    assert (ack.status, ack.command) == ('00', 'MD')
    assert len(scans) >= 10 and all(s.status == '99' for s in scans)
    stamps = np.array([s.timestamp_ms for s in scans])
    assert np.all(np.diff(stamps) % WRAP == 25)  # 40 scans/s, wrapping at 2**24
    sent = list(w.device.sent)[:len(scans)]
    for scan, rec in zip(scans, sent):
        assert scan.timestamp_ms == rec.timestamp_ms and scan.ranges_m.size == 1081
        assert np.array_equal(scan.raw, rec.raw)
    exp = np.concatenate([r.expected for r in sent])
    assert np.isposinf(exp).any() and np.isneginf(exp).any() and np.isnan(exp).any()
    raw = np.concatenate([r.raw for r in sent])
    assert np.all((raw[np.isneginf(exp)] >= 20) & (raw[np.isneginf(exp)] < 23))  # < DMIN
    assert np.all(raw[np.isposinf(exp)] <= 6) and np.all(
        (raw[np.isnan(exp)] >= 7) & (raw[np.isnan(exp)] <= 19))
    finite = np.isfinite(exp)
    assert np.array_equal(exp[finite], (raw[finite] / 1000.0).astype(np.float32))
    # the reply leaves once the scan passed AMAX: 1081 steps of 25 ms / 1440 after step 0
    rec = sent[-1]
    assert rec.sent_time - rec.step0_time == pytest.approx(1081 * 0.025 / 1440, abs=1e-9)
    assert w.run(0.05, b'QT\n')[0].command == 'QT'
    assert w.run(0.2) == []  # stream stopped


def test_cluster_skip_count_and_intensities():
    w = urg()
    items = w.run(0.5, b'ME0100040003103;ab\n')
    ack, *scans = items
    assert ack.status == '00' and len(scans) == 3  # three scans, then the stream ends
    assert [s.remaining_scans for s in scans] == [2, 1, 0]
    assert np.all(np.diff([s.timestamp_ms for s in scans]) == 50)  # every 2nd scan
    assert all(s.tag == 'ab' and s.ranges_m.size == 101 and s.intensities.size == 101
               for s in scans)
    rec = w.device.sent[-1]
    # a cluster value is the smallest distance of its 3 steps (recomputed from a GD scan
    # of single steps of a fresh device with the same noise)
    w2 = urg()
    w2.run(0.01, b'BM\n')
    single = w2.device
    scans2 = w2.run(0.5, b'MD0100040001103\n')[1:]
    assert len(scans2) == 3
    steps = single.sent[-1].raw
    groups = [steps[i:i + 3] for i in range(0, 301, 3)]
    want = [min(g[g >= 20]) if (g >= 20).any() else g[0] for g in groups]
    assert rec.raw.tolist() == want
    assert w.run(0.3) == []


def test_serial_line_rate_limits_the_scans_and_ss_switches_it():
    w = urg(URG_04LX)  # RS-232 at 19200 baud: 2.1 kB take 1.1 s per scan
    w.run(3.0, b'MD0044072501000\n')
    sent = list(w.device.sent)
    gaps = np.diff([s.sent_time for s in sent])
    assert 1.0 < np.median(gaps) < 1.3
    size = 16 + 4 + 6 + 682 * 3 + 2 * 32 + 1  # echo, status, time, 32 data lines, LF
    assert sent[-1].sent_time - sent[-1].step0_time == pytest.approx(
        726 * 0.1 / 1024 + size * 10 / 19200, abs=1e-9)
    w.run(1.5, b'QT\n')
    assert w.run(0.01, b'SS019200\n')[0].status == '03'
    assert w.run(0.01, b'SS012345\n')[0].status == '02'
    assert w.run(0.01, b'SS115200\n')[0].status == '00'
    n = len(w.device.sent)
    w.run(2.0, b'MD0044072501000\n')
    gaps = np.diff([s.sent_time for s in list(w.device.sent)[n:]])
    assert np.median(gaps) == pytest.approx(0.2, abs=0.01)  # every 2nd scan at 115200


def test_cr_changes_the_scan_speed():
    w = urg()
    assert w.run(0.01, b'CR05\n') == []  # CR is not in the host decoder's repertoire
    assert w.log[-1][1] == b'CR05\n00P\n\n'
    items = _frames(w.run(0.5, b'MD0000108001000\n'), scip2.ScanFrame)
    d = np.diff([s.timestamp_ms for s in items])
    assert np.mean(d) == pytest.approx(25.0 / 0.95, abs=0.1)
    assert w.raw(0.01, b'CR05\n').startswith(b'CR05\n03')
    assert w.raw(0.01, b'CR42\n').startswith(b'CR42\n02')


def test_delivery_jitter_keeps_the_order():
    w = urg(jitter=0.003, seed=4)
    items = w.run(1.0, b'MD0000108001000\n')[1:]
    stamps = [s.timestamp_ms for s in items]
    assert stamps == sorted(stamps) and len(stamps) >= 38
    delays = np.array([s.sent_time - s.step0_time for s in w.device.sent]) - 1081 * 0.025 / 1440
    assert delays.min() >= 0.0 and delays.std() > 0.002


def test_disconnect_switches_the_laser_off():
    w = urg()
    w.run(0.1, b'MD0000108001000\n')
    w.device.disconnected()
    assert w.run(0.2) == [] and not w.device.laser_on


def test_scene_motion_changes_the_scans():
    fixed = LaserScene(SceneConfig(motion='fixed', p_error=0, p_close=0))
    turning = LaserScene(SceneConfig(motion='rotate', yaw_rate=0.5, p_error=0, p_close=0))
    assert fixed.pose_at(2.0) == pytest.approx(fixed.pose_at(0.0))
    assert turning.pose_at(2.0)[2] == pytest.approx(turning.pose_at(0.0)[2] + 1.0)
    circle = LaserScene(SceneConfig(motion='circle', speed=0.3, radius=0.6))
    p0, p1 = circle.pose_at(0.0), circle.pose_at(math.pi * 0.6 / 0.3)  # half a lap
    assert math.hypot(p1[0] - p0[0], p1[1] - p0[1]) == pytest.approx(1.2)
    with pytest.raises(ValueError):
        SceneConfig(motion='fly')


# ---------------------------------------------------------------------------- LMS


def test_lms_byte_examples_of_protocols_md():
    w = lms()
    assert w.raw(0.1, bytes.fromhex('02000A0020005349434B5F4C4D53BEC5')) == \
        bytes.fromhex('06') + bytes.fromhex('028003' '00A000 10160A'.replace(' ', ''))
    assert w.raw(0.1, lms2xx.request_installation_mode('WRONG_PW')) == \
        bytes.fromhex('06028003' '00A001 10140B'.replace(' ', ''))
    w.run(0.1, lms2xx.request_baud(500000))
    w.run(0.1, lms2xx.request_variant(180, 100))
    data = w.raw(0.2, bytes.fromhex('0200020030013118'))  # one scan
    assert data[0] == 0x06 and data[1:8] == bytes.fromhex('02806E01B0B540')
    assert len(data) == 1 + 372


def test_lms_requests_and_replies():
    w = lms()
    items = w.run(0.1, lms2xx.request_type())
    assert isinstance(items[0], lms2xx.Ack) and items[1].text == 'LMS200;30106'
    status, = _frames(w.run(0.5, lms2xx.request_status()), lms2xx.Telegram)
    assert status.command == 0xB1 and len(status.data) == 152
    assert struct.unpack_from('<H', status.data, 120)[0] == 0x42  # 9600 baud code
    bb, = _frames(w.run(0.1, lms2xx.request_variant(100, 25)), lms2xx.VariantReply)
    assert bb.accepted and (bb.angle_deg, bb.resolution_cdeg) == (100, 25)
    refused = lms2xx.encode_telegram(0x3B, struct.pack('<HH', 180, 25))
    bb, = _frames(w.run(0.1, refused), lms2xx.VariantReply)
    assert not bb.accepted and (bb.angle_deg, bb.resolution_cdeg) == (100, 25)
    bad, = _frames(w.run(0.1, lms2xx.encode_telegram(0x55)), lms2xx.Telegram)
    assert bad.command == 0x92
    corrupt = bytearray(lms2xx.request_type())
    corrupt[-1] ^= 0x40
    assert _frames(w.run(0.1, bytes(corrupt)), lms2xx.Nak) and w.device.naks == 1


def test_lms_units_need_installation_mode():
    w = lms()
    block = _frames(w.run(0.2, lms2xx.request_config()), lms2xx.Telegram)[0].data
    assert lms2xx.config_units(block) == 'mm'
    cm = lms2xx.with_config(block, units='cm')
    f7, = _frames(w.run(0.3, lms2xx.request_write_config(cm)), lms2xx.Telegram)
    assert f7.command == 0xF7 and f7.data[0] == 0  # refused outside installation mode
    w.run(0.2, lms2xx.request_installation_mode())
    f7, = _frames(w.run(0.3, lms2xx.request_write_config(cm)), lms2xx.Telegram)
    assert f7.data[0] == 1 and w.device.units == 'cm'
    scan, = _frames(w.run(1.5, lms2xx.request_scan()), lms2xx.MeasuredValues)
    assert scan.units == 'cm' and scan.count == 361


@pytest.mark.parametrize('angle,res,units', [(180, 50, 'mm'), (100, 25, 'cm'),
                                             (180, 100, 'mm')])
def test_lms_stream_values_and_rep117(angle, res, units):
    w = lms(angle_deg=angle, resolution_cdeg=res, units=units, baud=500000)
    items = w.run(0.6, lms2xx.request_continuous())
    scans = _frames(items, lms2xx.MeasuredValues)
    passes = {100: 1, 50: 2, 25: 4}[res]
    assert len(scans) >= int(0.5 / (passes / 75.0)) - 1
    sent = list(w.device.sent)[:len(scans)]
    range_min, range_max = range_limits(units)
    for scan, rec in zip(scans, sent):
        assert scan.count == angle * 100 // res + 1 and scan.units == units
        assert np.array_equal(scan.raw, rec.raw)
        # REP 117 as a driver maps it: 0 units -> -inf, specials from the decoder
        mapped = np.where(scan.raw == 0, -np.inf, scan.ranges_m).astype(np.float32)
        assert np.array_equal(mapped, rec.expected, equal_nan=True)
        finite = np.isfinite(rec.expected)
        assert np.all((rec.expected[finite] >= range_min) & (rec.expected[finite] <= range_max))
    exp = np.concatenate([r.expected for r in sent])
    assert np.isposinf(exp).any() and np.isneginf(exp).any() and np.isnan(exp).any()
    # dazzle values carry the dazzle flag in the default measuring mode
    dazzled = np.concatenate([s.raw == 0x1FFE for s in scans])
    flags = np.concatenate([s.flags['dazzle'] for s in scans])
    assert np.array_equal(flags.astype(bool), dazzled)
    # scans start on the 75 Hz grid, `passes` revolutions apart
    starts = np.array([r.first_time for r in sent])
    assert np.allclose(np.diff(starts), passes / 75.0)
    assert _frames(w.run(0.1, lms2xx.request_stop_continuous()), lms2xx.ModeSwitchReply)
    assert _frames(w.run(0.3), lms2xx.MeasuredValues) == []


def test_lms_baud_switch_limits_the_stream():
    w = lms(baud=9600)
    w.run(0.1, lms2xx.request_baud(38400))
    assert w.device.baud == 38400
    w.run(2.0, lms2xx.request_continuous())
    gaps = np.diff([s.sent_time for s in w.device.sent])
    # 732 bytes at 38400 baud take 0.19 s: every 8th 0.5 deg scan (16 revolutions of 1/75 s)
    # reaches the host, 4.7 scans/s
    assert np.median(gaps) == pytest.approx(16 / 75.0, abs=1e-6)


def test_lms_reset_is_deaf_then_announces_itself_at_9600():
    w = lms(reset_delay=0.5)
    w.run(0.1, lms2xx.request_baud(500000))
    items = w.run(0.1, lms2xx.request_reset())
    assert _frames(items, lms2xx.Telegram)[0].command == 0x91
    assert w.run(0.1, lms2xx.request_type()) == []  # resetting: no ACK, no reply
    power_on, = _frames(w.run(0.5), lms2xx.Telegram)
    assert power_on.command == 0x90 and w.device.baud == 9600


def test_lms_without_acks_still_replies():
    w = lms(ack=False)
    items = w.run(0.1, lms2xx.request_type())
    assert [type(i).__name__ for i in items] == ['TypeReply']


# ---------------------------------------------------------------------------- CLI


def test_emulate_cli_options():
    parser = build_parser()
    args = parser.parse_args(['emulate', 'urg', '--model', 'urg-04lx', '--baud', '115200',
                              '--pose', '2,3,0.5', '--motion', 'rotate', '--clock-start-ms',
                              '16770000', '--jitter-ms', '2'])
    from landmark_nav.emulators import urg as urg_module
    device = urg_module.make_device(args)
    assert device.model is URG_04LX and device.default_baud == 115200
    assert device.scene.config.pose == (2.0, 3.0, 0.5)
    assert device.counter(0.0) == 16770000
    args = parser.parse_args(['emulate', 'lms200', '--variant', '100,25', '--units', 'cm',
                              '--no-ack'])
    from landmark_nav.emulators import lms200 as lms_module
    device = lms_module.make_device(args)
    assert (device.angle_deg, device.resolution_cdeg, device.units, device.ack) == \
        (100, 25, 'cm', False)
    with pytest.raises(SystemExit):
        parser.parse_args(['emulate', 'urg', '--pose', '1,2'])
