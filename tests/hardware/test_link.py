"""The controller's UDP endpoint, on loopback with ephemeral ports."""

import socket

import numpy as np
import pytest

from cdpm_drake.hardware.link import LinkError, ReelLink
from cdpm_drake.hardware.protocol import Status, decode_command, encode_status

M = 4


def _udp():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(1.0)
    return s


def _status(seq, **kw):
    base = dict(sequence=seq, time=0.01 * seq, lengths=np.full(M, 1.0 + seq * 1e-3),
                force=np.zeros(3))
    base.update(kw)
    return encode_status(Status(**base), check=False)


@pytest.fixture
def pair():
    bridge = _udp()
    link = ReelLink(M, bridge=bridge.getsockname())
    yield link, bridge
    link.close()
    bridge.close()


def _settle(link):
    # Loopback delivery is immediate, but leave no room for doubt.
    assert link.wait(1.0)


def test_binds_to_loopback_on_a_free_port_by_default(pair):
    link, _ = pair
    host, port = link.local_address
    assert host == "127.0.0.1" and port > 0


def test_commands_reach_the_bridge_with_increasing_sequence_numbers(pair):
    link, bridge = pair
    for k in range(3):
        link.send_command(np.full(M, 0.1 * k), enable=True, echo_sequence=7, echo_time=0.5,
                          time=0.002 * k)
    got = [decode_command(bridge.recvfrom(4096)[0], M) for _ in range(3)]
    assert [c.sequence for c in got] == [1, 2, 3]
    np.testing.assert_array_equal(got[2].velocity, np.full(M, 0.2))
    assert got[0].echo_sequence == 7 and got[0].enable
    assert link.counters.sent == 3 and link.last_sent_sequence == 3


def test_receive_returns_the_newest_valid_status_and_counts_gaps(pair):
    link, bridge = pair
    for seq in (1, 2, 5):
        bridge.sendto(_status(seq), link.local_address)
    _settle(link)
    status = link.receive(None)
    assert status.sequence == 5
    np.testing.assert_allclose(status.lengths, 1.005)
    c = link.counters
    # 1 -> 2 consecutive, 2 -> 5 skips 3 and 4.
    assert (c.received, c.accepted, c.lost) == (3, 3, 2)
    assert link.receive(5) is None  # nothing waiting: no block, no status


def test_old_and_repeated_statuses_are_rejected_against_the_callers_last(pair):
    link, bridge = pair
    for seq in (9, 10, 10, 8):
        bridge.sendto(_status(seq), link.local_address)
    _settle(link)
    # The caller (the Drake system) last accepted 9: only 10 is new; 9 again, the repeat of 10
    # and 8 are not.
    status = link.receive(9)
    assert status.sequence == 10
    assert link.counters.rejected["sequence"] == 3
    assert "older than the last accepted 10" in link.last_error


def test_datagrams_from_another_sender_are_ignored_and_counted(pair):
    link, bridge = pair
    intruder = _udp()
    try:
        intruder.sendto(_status(50), link.local_address)   # valid, but not from the bridge
        bridge.sendto(_status(3), link.local_address)
        _settle(link)
        status = link.receive(None)
        assert status.sequence == 3
        assert link.counters.foreign == 1 and link.counters.received == 1
        # Same address, different port is another sender too.
        intruder.sendto(_status(60), link.local_address)
        _settle(link)
        assert link.receive(3) is None and link.counters.foreign == 2
    finally:
        intruder.close()


def test_invalid_datagrams_are_counted_by_reason(pair):
    link, bridge = pair
    good = _status(4)
    bridge.sendto(good[:-1], link.local_address)                        # length
    bridge.sendto(b"JUNK" + good[4:], link.local_address)               # magic
    bridge.sendto(good[:-4] + bytes(4), link.local_address)            # crc
    bridge.sendto(_status(5, lengths=np.full(M, np.nan)), link.local_address)  # value
    _settle(link)
    assert link.receive(None) is None
    r = link.counters.rejected
    assert (r["length"], r["magic"], r["crc"], r["value"]) == (1, 1, 1, 1)
    assert link.counters.accepted == 0
    assert "lengths of cable 1 is nan m" in link.last_error


def test_a_closed_bridge_port_never_raises_in_the_control_loop():
    probe = _udp()
    closed_port = probe.getsockname()
    probe.close()  # nothing listens there now
    with ReelLink(M, bridge=closed_port) as link:
        for _ in range(3):
            link.send_command(np.zeros(M), enable=False, echo_sequence=None)
            link.receive(None)
        # Whatever the system reports about the closed port, nothing raised and nothing came.
        assert link.last_sent_sequence == 3
        assert link.counters.accepted == 0 and link.counters.received == 0


def test_bad_addresses_and_busy_ports_are_named():
    with pytest.raises(ValueError, match=r"address must be an IPv4 address .* got '10.0.0.256'"):
        ReelLink(M, bridge=("10.0.0.256", 47100))
    with pytest.raises(ValueError, match=r"local_address must be .* got 'my-laptop'"):
        ReelLink(M, bridge=("127.0.0.1", 47100), local=("my-laptop", 0))
    taken = _udp()
    try:
        with pytest.raises(LinkError, match=r"cannot bind the reel link to 127.0.0.1:\d+ "
                                            r"\(local_address, local_port\)"):
            ReelLink(M, bridge=("127.0.0.1", 47100), local=taken.getsockname())
    finally:
        taken.close()
