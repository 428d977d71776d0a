"""The encoder zero (cdpm_drake.kernels.encoder_zero): homed encoders less the homing's
stretch are the unstretched lengths, by the cable law T = EA (l - L0) / L0 solved here for
L0; the first measured tensions when every cable has one, else the statics, and never a
change once reconciled."""

import numpy as np

from cdpm_drake.kernels.encoder_zero import encoder_zero_sizes, encoder_zero_tick, homing_stretch

EA = 70000.0
M = 4


def _ticks(encoders, measured, home, window):
    """Feed (encoders, measured) tick by tick, the memory carried as the block's delay does;
    returns (lengths, reconciled, returned status) of each tick."""
    s = encoder_zero_sizes(M)
    params = np.concatenate([[EA, float(window)], home])
    memory = np.zeros(s["memory"])
    out = np.empty(s["out"])
    seen = []
    for enc, T in zip(encoders, measured):
        status = encoder_zero_tick(params, np.concatenate([enc, T, memory]), out)
        memory = out[s["memory_at"]:].copy()
        seen.append((out[:M].copy(), out[M], status))
    return seen


def test_the_homing_stretch_is_what_the_cable_law_stretches_the_unstretched_length_by():
    rigid = np.array([1.2, 2.5, 3.1, 0.8])
    T = np.array([5.0, 40.0, 0.0, -3.0])  # a slack cable (T < 0) has no stretch
    L0 = rigid / (1.0 + np.maximum(T, 0.0) / EA)  # T = EA (l - L0) / L0
    out = np.empty(M)
    homing_stretch(rigid, T, EA, out)
    np.testing.assert_allclose(rigid - out, L0, rtol=0, atol=1e-15)
    assert out[2] == 0.0 and out[3] == 0.0
    # 40 N on 2.5 m of 70 kN cable: 40 * 2.5 / 70040 = 1.428 mm.
    assert abs(out[1] - 40.0 * 2.5 / 70040.0) < 1e-15


def test_measured_tensions_reconcile_when_every_cable_has_one_and_hold_from_then():
    rigid = np.array([1.2, 2.5, 3.1, 0.8])
    home = np.array([10.0, 10.0, 10.0, 10.0])  # the statics' guess
    true = np.array([6.0, 22.0, 14.0, 9.0])
    nan = np.full(M, np.nan)
    partial = true.copy()
    partial[2] = np.nan
    moved = rigid + 0.003  # the reels paid out 3 mm after the reconciliation
    seen = _ticks([rigid, rigid, rigid, moved], [nan, partial, true, true * 3], home,
                  window=10)
    # Ticks 1-2: not every cable measured: the statics, not reconciled.
    for lengths, flag, status in seen[:2]:
        np.testing.assert_allclose(lengths, rigid / (1 + home / EA), rtol=0, atol=1e-15)
        assert flag == 0.0 and status == 0
    # Tick 3: every cable measured: reconciled on them.
    np.testing.assert_allclose(seen[2][0], rigid / (1 + true / EA), rtol=0, atol=1e-15)
    assert seen[2][1] == 1.0 and seen[2][2] == 1
    # Then held: the payout passes through, later tensions change nothing.
    np.testing.assert_allclose(seen[3][0], moved - (rigid - rigid / (1 + true / EA)),
                               rtol=0, atol=1e-15)


def test_without_a_reading_the_statics_reconcile_at_the_window():
    """window 1 (a plant without a tension sensor): the statics at once; window 3 with a
    cable never measured: the measured ones and the statics for that cable at tick 3."""
    rigid = np.array([1.2, 2.5, 3.1, 0.8])
    home = np.array([12.0, 7.0, 30.0, 5.0])
    nan = np.full(M, np.nan)
    seen = _ticks([rigid], [nan], home, window=1)
    np.testing.assert_allclose(seen[0][0], rigid / (1 + home / EA), rtol=0, atol=1e-15)
    assert seen[0][1] == 1.0
    partial = np.array([8.0, np.nan, 25.0, 6.0])
    seen = _ticks([rigid] * 4, [partial] * 4, home, window=3)
    assert [flag for _, flag, _ in seen] == [0.0, 0.0, 1.0, 1.0]
    expected = np.where(np.isnan(partial), home, partial)
    np.testing.assert_allclose(seen[2][0], rigid / (1 + expected / EA), rtol=0, atol=1e-15)
    np.testing.assert_allclose(seen[3][0], seen[2][0], rtol=0, atol=0)

