"""The reel-link datagrams: layout per hardware/PROTOCOL.md, round trips, every rejection."""

import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from cdpm_drake.hardware import protocol as P
from cdpm_drake.hardware.protocol import (Command, ProtocolError, SequenceTracker, Status,
                                          check_sequence, decode_command, decode_status,
                                          encode_command, encode_status)

U32 = st.integers(0, 2**32 - 1)
TIME = st.floats(0.0, 1e9, allow_nan=False)


def _status(m=7, **kw):
    base = dict(sequence=41, time=12.5, lengths=np.linspace(1.0, 3.0, m),
                force=np.array([1.0, -2.0, 3.5]), faults=0, enabled=True, echo_sequence=17,
                echo_time=12.25, commands_lost=2)
    base.update(kw)
    return Status(**base)


def _command(m=7, **kw):
    base = dict(sequence=18, time=12.25, velocity=np.linspace(-0.2, 0.2, m), enable=True,
                echo_sequence=40, echo_time=12.498)
    base.update(kw)
    return Command(**base)


def _resign(data: bytes) -> bytes:
    """Recompute the CRC trailer, so a test reaches the checks after the CRC."""
    body = data[:-4]
    return body + struct.pack("<I", zlib.crc32(body))


def _patch(data: bytes, offset: int, fmt: str, value) -> bytes:
    buf = bytearray(data)
    struct.pack_into(fmt, buf, offset, value)
    return _resign(bytes(buf))


# --- layout ----------------------------------------------------------------------------------


def test_sizes_follow_the_tables_in_protocol_md():
    # Command: 32-byte header + 8 bytes per cable + 4-byte CRC = 92 for 7 cables.
    # Status: header + faults, commands_lost (8) + 8 per cable + force (24) + CRC = 124.
    assert P.command_size(7) == 92 and len(encode_command(_command())) == 92
    assert P.status_size(7) == 124 and len(encode_status(_status())) == 124
    assert P.command_size(8) == 100 and P.status_size(8) == 132


def test_command_bytes_sit_at_the_documented_offsets():
    v = np.array([0.5, -0.25, 0.0])
    data = encode_command(Command(sequence=0x01020304, time=2.0, velocity=v, enable=True,
                                  echo_sequence=9, echo_time=1.5))
    # Offsets from the header and command tables of PROTOCOL.md.
    assert data[0:4] == b"CDPC"
    assert data[4] == 1 and data[5] == 3
    assert struct.unpack_from("<H", data, 6)[0] == 0x3  # ECHO_VALID | ENABLE
    assert data[8:12] == bytes([4, 3, 2, 1])  # little-endian sequence
    assert struct.unpack_from("<I", data, 12)[0] == 9
    assert struct.unpack_from("<dd", data, 16) == (2.0, 1.5)
    assert struct.unpack_from("<3d", data, 32) == (0.5, -0.25, 0.0)
    assert struct.unpack_from("<I", data, 56)[0] == zlib.crc32(data[:56])


def test_status_bytes_sit_at_the_documented_offsets():
    data = encode_status(_status(m=2, lengths=np.array([1.25, 2.5]), faults=0x11,
                                 commands_lost=7, enabled=False, echo_sequence=None))
    assert data[0:4] == b"CDPS" and data[5] == 2
    assert struct.unpack_from("<H", data, 6)[0] == 0  # neither ENABLED nor ECHO_VALID
    assert struct.unpack_from("<II", data, 32) == (0x11, 7)
    assert struct.unpack_from("<2d", data, 40) == (1.25, 2.5)
    assert struct.unpack_from("<3d", data, 56) == (1.0, -2.0, 3.5)
    assert struct.unpack_from("<I", data, 80)[0] == zlib.crc32(data[:80])


# --- round trips -----------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 64), seq=U32, echo=st.one_of(st.none(), U32), t=TIME, te=TIME,
       enable=st.booleans(), data=st.data())
def test_command_round_trip_is_exact(m, seq, echo, t, te, enable, data):
    v = np.array(data.draw(st.lists(st.floats(-10.0, 10.0), min_size=m, max_size=m)))
    c = Command(sequence=seq, time=t, velocity=v, enable=enable, echo_sequence=echo,
                echo_time=te)
    back = decode_command(encode_command(c), m)
    assert (back.sequence, back.time, back.enable, back.echo_sequence) == (seq, t, enable, echo)
    assert back.echo_time == te
    np.testing.assert_array_equal(back.velocity, v)  # f64 on the wire: bit-exact


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 64), seq=U32, faults=U32, lost=U32, enabled=st.booleans(),
       echo=st.one_of(st.none(), U32), data=st.data())
def test_status_round_trip_is_exact(m, seq, faults, lost, enabled, echo, data):
    lengths = np.array(data.draw(st.lists(st.floats(0.0, 100.0), min_size=m, max_size=m)))
    force = np.array(data.draw(st.lists(st.floats(-2000.0, 2000.0), min_size=3, max_size=3)))
    s = Status(sequence=seq, time=3.0, lengths=lengths, force=force, faults=faults,
               enabled=enabled, echo_sequence=echo, echo_time=2.0, commands_lost=lost)
    back = decode_status(encode_status(s), m)
    assert (back.sequence, back.faults, back.commands_lost, back.enabled,
            back.echo_sequence) == (seq, faults, lost, enabled, echo)
    np.testing.assert_array_equal(back.lengths, lengths)
    np.testing.assert_array_equal(back.force, force)


# --- rejections ------------------------------------------------------------------------------


def _reject(data, m, reason, match, decode=decode_status):
    with pytest.raises(ProtocolError, match=match) as info:
        decode(data, m)
    assert info.value.reason == reason


def test_wrong_magic_names_both_and_spots_a_command_sent_as_status():
    good = encode_status(_status())
    _reject(b"XXXX" + good[4:], 7, "magic", r"magic is b'XXXX', expected b'CDPS'")
    # A command datagram arriving where a status is expected (e.g. ports swapped).
    cmd = encode_command(_command())
    _reject(cmd, 7, "magic", r"that is a command datagram")


def test_wrong_version_is_rejected_even_with_a_good_crc():
    _reject(_patch(encode_status(_status()), 4, "<B", 3), 7, "version", r"version is 3")
    # A receiver that settled on version 1 refuses a version-2 datagram (and the reverse).
    _reject(encode_status(_status(version=2)), 7, "version", r"version is 2, this link "
            r"speaks version 1", decode=lambda d, m: decode_status(d, m, versions=(1,)))
    _reject(encode_command(_command()), 7, "version", r"version is 1",
            decode=lambda d, m: decode_command(d, m, versions=(2,)))


def test_wrong_cable_count_names_the_expected_count():
    # An 8-cable datagram reaching a 7-cable controller.
    _reject(encode_status(_status(m=8)), 7, "cable_count", r"cable_count is 8, expected 7")
    _reject(encode_command(_command(m=6)), 7, "cable_count", r"cable_count is 6",
            decode=decode_command)


@pytest.mark.parametrize("cut", [0, 31, 123, 125])
def test_wrong_length_is_rejected(cut):
    good = encode_status(_status())
    data = good[:cut] if cut < len(good) else good + b"\0" * (cut - len(good))
    _reject(data, 7, "length", rf"{cut} bytes")


def test_undefined_flag_bits_are_rejected():
    _reject(_patch(encode_status(_status()), 6, "<H", 0x0008), 7, "flags", r"0x0008")
    # ENABLE (0x2) is a command flag; 0x4 is defined for neither.
    _reject(_patch(encode_command(_command()), 6, "<H", 0x0006), 7, "flags", r"0x0004",
            decode=decode_command)


@settings(max_examples=80, deadline=None)
@given(position=st.integers(0, 123), xor=st.integers(1, 255))
def test_any_single_corrupted_byte_is_rejected(position, xor):
    # CRC-32 detects every burst error of up to 32 bits, so one flipped byte anywhere (the
    # CRC included) must be refused, by the CRC check or by an earlier one.
    buf = bytearray(encode_status(_status()))
    buf[position] ^= xor
    with pytest.raises(ProtocolError) as info:
        decode_status(bytes(buf), 7)
    assert info.value.reason in ("magic", "version", "cable_count", "flags", "crc")


def test_bad_crc_message_gives_both_values():
    buf = bytearray(encode_status(_status()))
    buf[50] ^= 0x01
    _reject(bytes(buf), 7, "crc", r"crc is 0x[0-9a-f]{8}, the datagram's bytes give 0x")


@pytest.mark.parametrize("field,index,value,match", [
    ("lengths", 2, np.nan, r"lengths of cable 3 is nan m"),
    ("lengths", 0, -0.001, r"lengths of cable 1 is -0.001 m, outside \[0, 100\] m"),
    ("lengths", 6, 100.5, r"lengths of cable 7 is 100.5 m"),
    ("lengths", 1, np.inf, r"lengths of cable 2 is inf m"),
    ("force", 1, np.nan, r"force\[y\] is nan N"),
    ("force", 2, -2000.5, r"force\[z\] is -2000.5 N, outside \[-2000, 2000\] N"),
])
def test_bad_status_values_are_rejected_by_name(field, index, value, match):
    s = _status()
    arr = getattr(s, field).copy()
    arr[index] = value
    data = encode_status(_status(**{field: arr}), check=False)  # a broken bridge
    _reject(data, 7, "value", match)
    with pytest.raises(ProtocolError, match=match):
        encode_status(_status(**{field: arr}))  # and we never build one ourselves


@pytest.mark.parametrize("t,match", [(np.nan, r"time is nan s"), (-1.0, r"time is -1.0 s"),
                                     (2e9, r"time is 2000000000.0 s")])
def test_bad_timestamps_are_rejected(t, match):
    data = encode_status(_status(time=t), check=False)
    _reject(data, 7, "value", match)


def test_a_nan_or_too_fast_command_is_never_encoded_nor_accepted():
    v = np.zeros(7)
    v[4] = np.nan
    with pytest.raises(ProtocolError, match=r"velocity of cable 5 is nan m/s"):
        encode_command(_command(velocity=v))
    v[4] = 10.5
    _reject(encode_command(_command(velocity=v), check=False), 7, "value",
            r"velocity of cable 5 is 10.5 m/s, outside \[-10, 10\] m/s", decode=decode_command)


def test_bad_values_on_encode_name_the_field():
    with pytest.raises(ProtocolError, match=r"sequence must be an integer in 0..4294967295, "
                                            r"got 4294967296"):
        encode_command(_command(sequence=2**32))
    with pytest.raises(ProtocolError, match=r"faults must be a 32-bit unsigned integer, got -1"):
        encode_status(_status(faults=-1))
    with pytest.raises(ProtocolError, match=r"cable count must be 1..64, got 65"):
        encode_status(_status(m=65))


# --- sequence numbers ------------------------------------------------------------------------


def test_sequence_ordering_with_wrap_around():
    top = 2**32 - 1
    assert check_sequence(5, None) == 0          # first datagram: anything goes
    assert check_sequence(5, 4) == 0             # consecutive
    assert check_sequence(9, 4) == 4             # 5, 6, 7, 8 skipped
    assert check_sequence(0, top) == 0           # wraps: 2^32-1 -> 0 is one step
    assert check_sequence(2, top - 1) == 3       # 4 steps across the wrap: top, 0, 1 skipped
    assert check_sequence(2**31 - 1, 0) == 2**31 - 2  # the farthest "newer"
    with pytest.raises(ProtocolError, match=r"sequence 4 repeats"):
        check_sequence(4, 4)
    with pytest.raises(ProtocolError, match=r"sequence 3 is 1 older than the last accepted 4"):
        check_sequence(3, 4)
    with pytest.raises(ProtocolError, match=r"is 1 older"):
        check_sequence(top, 0)                   # just before the wrap point: old
    with pytest.raises(ProtocolError) as info:
        check_sequence(2**31, 0)                 # exactly half way: ambiguous, refused
    assert info.value.reason == "sequence"


@settings(max_examples=40, deadline=None)
@given(start=U32, steps=st.lists(st.integers(1, 1000), min_size=1, max_size=50))
def test_tracker_counts_every_skipped_number_across_wraps(start, steps):
    tracker = SequenceTracker()
    tracker.accept(start)
    seq = start
    for step in steps:
        seq = (seq + step) % 2**32
        tracker.accept(seq)
        # Replaying the datagram just accepted, or the one before it, is refused.
        with pytest.raises(ProtocolError):
            tracker.accept(seq)
    # Each step of k numbers skips k - 1 of them.
    assert tracker.lost == sum(s - 1 for s in steps)
    assert tracker.last == seq


def test_fault_names_cover_the_documented_bits():
    assert P.fault_names(0x11) == ["ESTOP", "COMMAND_TIMEOUT"]
    assert P.fault_names(0x7F) == ["ESTOP", "DRIVE", "ENCODER", "FORCE_SENSOR",
                                   "COMMAND_TIMEOUT", "LENGTH_LIMIT", "OVERSPEED"]
    assert P.fault_names(1 << 9) == ["BIT9"]


# --- version 2: the drives' force, the reels' speed, a load cell (issue 31) --------------------


def test_version_2_status_bytes_sit_at_the_documented_offsets():
    """PROTOCOL.md's version-2 status table for m = 2: the version-1 body, then drive_force at
    80, reel_speed at 96, load_cell at 112 (f64 x m each), the CRC at 128; 132 bytes."""
    data = encode_status(_status(m=2, lengths=np.array([1.25, 2.5]), version=2,
                                 drive_force=np.array([-12.5, 3.0]),
                                 reel_speed=np.array([0.125, -0.5]),
                                 load_cell=np.array([np.nan, 7.75])))
    assert len(data) == 132 == P.status_size(2, version=2)
    assert data[4] == 2
    assert struct.unpack_from("<2d", data, 40) == (1.25, 2.5)
    assert struct.unpack_from("<3d", data, 56) == (1.0, -2.0, 3.5)
    assert struct.unpack_from("<2d", data, 80) == (-12.5, 3.0)
    assert struct.unpack_from("<2d", data, 96) == (0.125, -0.5)
    cell = struct.unpack_from("<2d", data, 112)
    assert np.isnan(cell[0]) and cell[1] == 7.75
    assert struct.unpack_from("<I", data, 128)[0] == zlib.crc32(data[:128])
    # 7 cables: 124 + 3 x 8 x 7 = 292 bytes.
    assert P.status_size(7, version=2) == 292


def test_hand_built_version_2_bytes_decode_to_their_fields():
    """A datagram packed by hand from the table (not by encode_status) decodes field by
    field; NaN in the drive arrays is "no reading" and passes."""
    m = 3
    body = (struct.pack("<4sBBHIIdd", b"CDPS", 2, m, 0x3, 77, 12, 4.5, 4.25)
            + struct.pack("<II", 0, 5)
            + struct.pack("<3d", 2.0, 2.5, 3.0) + struct.pack("<3d", 0.5, 0.0, -9.0)
            + struct.pack("<3d", -20.0, np.nan, 4.0)        # drive_force, N
            + struct.pack("<3d", 0.01, -0.02, np.nan)       # reel_speed, m/s
            + struct.pack("<3d", np.nan, np.nan, np.nan))   # load_cell: none
    data = body + struct.pack("<I", zlib.crc32(body))
    s = decode_status(data, m)
    assert (s.version, s.sequence, s.echo_sequence, s.enabled, s.commands_lost) == (
        2, 77, 12, True, 5)
    np.testing.assert_array_equal(s.lengths, [2.0, 2.5, 3.0])
    np.testing.assert_array_equal(s.drive_force, [-20.0, np.nan, 4.0])
    np.testing.assert_array_equal(s.reel_speed, [0.01, -0.02, np.nan])
    assert np.isnan(s.load_cell).all()
    # The same body sent as version 1 (its shorter length) decodes with no drive readings.
    v1 = (struct.pack("<4sBBHIIdd", b"CDPS", 1, m, 0x3, 77, 12, 4.5, 4.25) + body[32:88])
    s1 = decode_status(v1 + struct.pack("<I", zlib.crc32(v1)), m)
    assert s1.version == 1 and np.isnan(s1.drive_force).all()
    assert np.isnan(s1.reel_speed).all() and np.isnan(s1.load_cell).all()
    np.testing.assert_array_equal(s1.lengths, s.lengths)


@settings(max_examples=40, deadline=None)
@given(m=st.integers(1, 64), data=st.data())
def test_version_2_round_trip_is_exact_nan_included(m, data):
    def draw(hi):
        return np.array(data.draw(st.lists(st.one_of(st.floats(-hi, hi), st.just(np.nan)),
                                           min_size=m, max_size=m)), dtype=float)

    force, speed, cell = draw(1e5), draw(100.0), draw(1e5)
    s = _status(m=m, lengths=np.full(m, 2.0), version=2, drive_force=force, reel_speed=speed,
                load_cell=cell)
    back = decode_status(encode_status(s), m)
    assert back.version == 2
    for sent, got in ((force, back.drive_force), (speed, back.reel_speed),
                      (cell, back.load_cell)):
        np.testing.assert_array_equal(got, sent)  # NaN where NaN, bit-exact elsewhere


def test_absent_drive_arrays_encode_as_no_reading():
    back = decode_status(encode_status(_status(version=2)), 7)
    assert np.isnan(back.drive_force).all() and np.isnan(back.load_cell).all()


@pytest.mark.parametrize("field,value,match", [
    ("drive_force", np.inf, r"drive_force of cable 2 is inf N, outside \[-100000, 100000\] N"),
    ("reel_speed", -100.5, r"reel_speed of cable 2 is -100.5 m/s"),
    ("load_cell", 2e5, r"load_cell of cable 2 is 200000.0 N"),
])
def test_version_2_values_out_of_range_are_rejected_by_name(field, value, match):
    arr = np.zeros(7)
    arr[1] = value
    data = encode_status(_status(version=2, **{field: arr}), check=False)
    _reject(data, 7, "value", match)
    with pytest.raises(ProtocolError, match=match):
        encode_status(_status(version=2, **{field: arr}))


def test_a_version_2_command_is_a_version_1_command_with_another_version_byte():
    one = encode_command(_command())
    two = encode_command(_command(version=2))
    assert len(one) == len(two) == P.command_size(7)
    assert two[4] == 2 and one[:4] + one[5:-4] == two[:4] + two[5:-4]
    assert decode_command(two, 7).version == 2 and decode_command(one, 7).version == 1
