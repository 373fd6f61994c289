import numpy as np
import pytest
from tests.radar.radar_helpers import ula_params

from zendar_dataset.radar.cfar import (
    METHODS,
    CfarWindow,
    _os_detect_kernel,
    cfar_2d,
    cfar_alpha,
    default_os_rank,
    detect,
    ordered_statistic_reference,
)
from zendar_dataset.radar.fmcw import beat_signal_exact
from zendar_dataset.radar.range_doppler import range_doppler, window_values

GUARD, TRAIN = (2, 1), (4, 3)


def _reference_statistic(power, r, d, method, guard, train, rank=None):
    """Per-cell loop over the training cells (Doppler wraps, range mirrored)."""
    (gr, gd), (tr, td) = guard, train
    n_r, n_d = power.shape
    near, far = [], []
    for dr in range(-(gr + tr), gr + tr + 1):
        for dd in range(-(gd + td), gd + td + 1):
            if abs(dr) <= gr and abs(dd) <= gd:
                continue
            rr = abs(r + dr)
            rr = 2 * (n_r - 1) - rr if rr > n_r - 1 else rr
            value = power[rr, (d + dd) % n_d]
            (near if (dr < 0 or (dr == 0 and dd < 0)) else far).append(value)
    cells = np.array(near + far)
    if method == "ca":
        return cells.mean()
    if method == "so":
        return min(np.mean(near), np.mean(far))
    if method == "go":
        return max(np.mean(near), np.mean(far))
    return np.sort(cells)[rank - 1]


@pytest.mark.parametrize("method", METHODS)
def test_statistic_matches_per_cell_reference(method):
    rng = np.random.default_rng(0)
    power = rng.exponential(size=(40, 24))
    result = cfar_2d(power, method=method, guard=GUARD, train=TRAIN, pfa=1e-3)
    window = CfarWindow(*GUARD, *TRAIN)
    rank = default_os_rank(window.n_train)
    os_scale = np.sum(1.0 / (window.n_train - np.arange(rank)))
    for r, d in [(0, 0), (1, 23), (20, 12), (39, 5), (37, 0), (6, 22)]:
        expected = _reference_statistic(power, r, d, method, GUARD, TRAIN, rank)
        got = result.noise_power[r, d] * (os_scale if method == "os" else 1.0)
        assert got == pytest.approx(expected, rel=1e-9)
        assert result.threshold[r, d] == pytest.approx(result.alpha * expected, rel=1e-9)
    np.testing.assert_array_equal(result.mask, power > result.threshold)


def test_os_matches_scipy_rank_filter():
    rng = np.random.default_rng(1)
    power = rng.exponential(size=(64, 32))
    window = CfarWindow(*GUARD, *TRAIN)
    rank = 17
    result = cfar_2d(power, method="os", guard=GUARD, train=TRAIN, os_rank=rank)
    scale = np.sum(1.0 / (window.n_train - np.arange(rank)))
    np.testing.assert_allclose(result.noise_power * scale, ordered_statistic_reference(power, window, rank), rtol=1e-12)


def _os_mask_by_definition(power, guard, train, rank, alpha, edge):
    """OS-CFAR by its definition: per cell, sort the training ring, test ``x_cut > alpha * X_(k)``."""
    (gr, gd), (tr, td) = guard, train
    hr, hd = gr + tr, gd + td
    n_r, n_d = power.shape
    mask = np.zeros(power.shape, dtype=bool)
    for r in range(n_r):
        if edge == "valid-range" and not hr <= r < n_r - hr:
            continue
        for d in range(n_d):
            ring = []
            for dr in range(-hr, hr + 1):
                for dd in range(-hd, hd + 1):
                    if abs(dr) <= gr and abs(dd) <= gd:
                        continue
                    if edge == "wrap":
                        rr = (r + dr) % n_r
                    else:
                        rr = abs(r + dr)
                        rr = 2 * (n_r - 1) - rr if rr > n_r - 1 else rr
                    ring.append(float(power[rr, (d + dd) % n_d]))
            mask[r, d] = power[r, d] > alpha * sorted(ring)[rank - 1]
    return mask


OS_WINDOWS = [((1, 1), (2, 2)), ((2, 1), (4, 3)), ((0, 0), (1, 1)), ((1, 0), (2, 0)), ((0, 2), (3, 1))]


@pytest.mark.parametrize("edge", ["wrap-doppler", "wrap", "valid-range"])
@pytest.mark.parametrize(("guard", "train"), OS_WINDOWS)
def test_os_counting_mask_equals_the_definition_on_tied_maps(guard, train, edge):
    # Integer-valued maps: many ties inside the ring and between the CUT and the ring.
    rng = np.random.default_rng(sum(guard) * 10 + sum(train))
    n = CfarWindow(*guard, *train).n_train
    for trial, rank in enumerate(sorted({1, 2, default_os_rank(n), n - 1, n})):
        power = rng.integers(0, 4 + 8 * trial, size=(2, 26, 17)).astype(np.float64)
        power[:, 5, 3] = 60.0  # a certain detection
        pfa = [0.3, 0.05, 1e-3][trial % 3]
        result = cfar_2d(power, method="os", guard=guard, train=train, os_rank=rank, pfa=pfa, edge=edge)
        alpha = cfar_alpha("os", n, pfa, rank)
        for i in range(2):
            expected = _os_mask_by_definition(power[i], guard, train, rank, alpha, edge)
            np.testing.assert_array_equal(result.mask[i], expected)
        # the mask agrees with the full threshold map computed on demand
        np.testing.assert_array_equal(result.mask, power > result.threshold)


@pytest.mark.parametrize("alpha", [0.5, 1.0, 2.0, 3.0])
def test_os_counting_kernel_is_strict_at_exact_ties(alpha):
    # Factors that make alpha * X_(k) equal to the CUT on integer maps, where ">" versus ">=" matters.
    rng = np.random.default_rng(int(alpha * 10))
    guard, train = (1, 1), (2, 2)
    window = CfarWindow(*guard, *train)
    power = rng.integers(0, 5, size=(20, 15)).astype(np.float64)
    rows = np.abs(np.arange(-window.half_range, 20 + window.half_range))
    rows = np.where(rows > 19, 38 - rows, rows)
    cols = np.arange(-window.half_doppler, 15 + window.half_doppler) % 15
    padded = np.ascontiguousarray(power[rows][:, cols])[None]
    for rank in (1, 7, 20, window.n_train):
        mask = np.empty((1, 20, 15), dtype=bool)
        _os_detect_kernel(padded, alpha, 1, 1, window.half_range, window.half_doppler, rank, mask)
        expected = _os_mask_by_definition(power, guard, train, rank, alpha, "wrap-doppler")
        np.testing.assert_array_equal(mask[0], expected)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("edge", ["wrap-doppler", "valid-range"])
def test_noise_power_at_cells_equals_the_full_map(method, edge):
    rng = np.random.default_rng(11)
    power = rng.exponential(size=(2, 40, 24))
    result = cfar_2d(power, method=method, guard=GUARD, train=TRAIN, pfa=0.05, edge=edge)
    index = np.nonzero(result.mask | (rng.random(power.shape) < 0.05))
    at_cells = result.noise_power_at(*index)  # before the full map exists (OS computes it lazily)
    np.testing.assert_array_equal(at_cells, result.noise_power[index])
    assert np.isnan(result.noise_power_at(np.array([0]), np.array([0]), np.array([3]))[0]) == (edge == "valid-range")


@pytest.mark.parametrize("method", METHODS)
def test_false_alarm_rate_on_noise_within_20_percent(method):
    # 6 maps x 248 x 256 valid cells at pfa 1e-3: ~380 expected false alarms.
    rng = np.random.default_rng(42)
    noise = rng.standard_normal((6, 256, 256, 2)) @ np.array([1.0, 1j]) / np.sqrt(2)
    power = np.abs(noise) ** 2 * 3.7  # any noise level: CFAR must not care
    pfa = 1e-3
    result = cfar_2d(power, method=method, guard=(2, 2), train=(4, 4), pfa=pfa, edge="valid-range")
    hr = 6
    measured = result.mask[:, hr:-hr].mean()
    assert measured == pytest.approx(pfa, rel=0.2)
    assert not result.mask[:, :hr].any() and np.isinf(result.threshold[:, :hr]).all()


@pytest.mark.parametrize("method", METHODS)
def test_target_at_known_snr_is_detected(method):
    params = ula_params(n_samples=128, n_chirps=64, n_antennas=4)
    rng = np.random.default_rng(7)
    raw_shape = (64, 128, 4)
    noise = (rng.standard_normal(raw_shape) + 1j * rng.standard_normal(raw_shape)) / np.sqrt(2)
    # 13 dB per-cell SNR after integration: amplitude a gives a^2 (sum w_r)^2 (sum w_d)^2 per antenna,
    # noise gives sum w_r^2 sum w_d^2 per antenna.
    w_r, w_d = window_values("hann", 128), window_values("hann", 64)
    gain = (w_r.sum() * w_d.sum()) ** 2 / (np.sum(w_r**2) * np.sum(w_d**2))
    snr_db = 13.0
    amplitude = np.sqrt(10 ** (snr_db / 10) / gain)
    target = beat_signal_exact(params, [40 * params.range_bin_m, 0, 0], [7 * params.doppler_bin_mps, 0, 0], [amplitude])
    dets = detect(range_doppler(target + noise), params, method=method, guard=(2, 2), train=(6, 4), pfa=1e-4)
    hits = (dets.range_bin == 40) & (dets.doppler_bin == 32 + 7)
    assert hits.sum() == 1
    assert dets.range_m[hits][0] == pytest.approx(40 * params.range_bin_m)
    assert dets.velocity_mps[hits][0] == pytest.approx(7 * params.doppler_bin_mps)
    assert dets.snr_db[hits][0] == pytest.approx(snr_db, abs=2.5)
    assert len(dets) <= 3  # pfa 1e-4 over 8192 cells


def test_wrap_doppler_detects_target_at_the_doppler_edge():
    rng = np.random.default_rng(3)
    power = rng.exponential(size=(64, 32))
    power[30, 0] = 300.0
    power[30, 31] = 5.0
    result = cfar_2d(power, method="ca", guard=(1, 1), train=(3, 3), pfa=1e-4)
    assert result.mask[30, 0]
    # (30, 0) lies in the training window of (30, 28) only through the wrap
    assert result.noise_power[30, 28] > result.noise_power[30, 20] + 300.0 / result.n_train * 0.5


def test_wrap_mode_wraps_range_too():
    power = np.ones((32, 16))
    power[0, 5] = 1000.0
    wrapped = cfar_2d(power, guard=(1, 1), train=(2, 2), edge="wrap")
    mirrored = cfar_2d(power, guard=(1, 1), train=(2, 2))
    assert wrapped.noise_power[29, 5] > 1.5
    assert mirrored.noise_power[29, 5] == pytest.approx(1.0)


def test_batch_of_maps_equals_each_map():
    rng = np.random.default_rng(5)
    power = rng.exponential(size=(3, 48, 20))
    for method in METHODS:
        batched = cfar_2d(power, method=method, guard=GUARD, train=TRAIN)
        for i in range(3):
            single = cfar_2d(power[i], method=method, guard=GUARD, train=TRAIN)
            np.testing.assert_allclose(batched.threshold[i], single.threshold)


def test_invalid_arguments():
    power = np.ones((32, 16))
    with pytest.raises(ValueError, match="method"):
        cfar_2d(power, method="xx")
    with pytest.raises(ValueError, match="edge"):
        cfar_2d(power, edge="mirror-all")
    with pytest.raises(ValueError, match="pfa"):
        cfar_2d(power, pfa=0.0)
    with pytest.raises(ValueError, match="Doppler cells"):
        cfar_2d(power, guard=(1, 4), train=(1, 4))
    with pytest.raises(ValueError, match="non-negative"):
        cfar_2d(power, guard=(-1, 1))
    with pytest.raises(ValueError, match="os_rank"):
        cfar_2d(power, method="os", os_rank=1000)
    with pytest.raises(ValueError, match="real"):
        cfar_2d(power + 0j)
    with pytest.raises(ValueError, match="params"):
        detect(power)
