"""Local view cells: exact matching against brute-force loops, learning, state, sensors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import example, given, settings
from hypothesis import strategies as st

import torchratslam.pipeline.defaults  # noqa: F401  (registers the default stages)
from torchratslam.config import LocalViewParams, load_config
from torchratslam.errors import ConfigError, InputError, MapFormatError
from torchratslam.local_view.bank import TemplateBank
from torchratslam.local_view.view import FeatureView, LocalView
from torchratslam.messages import Frame
from torchratslam.registry import LOCAL_VIEWS

# ----------------------------------------------------------------- reference loops


def brute_force(bank: np.ndarray, view: np.ndarray, panoramic: bool, shift: int, step: int):
    """OpenRatSLAM's comparison, one template and one offset at a time (float64).

    Returns (template id, offset, mean error) with ties to the lowest id, then offset.
    """
    y, x = view.shape
    best = (math.inf, -1, -1)
    for t in range(bank.shape[0]):
        tmpl = bank[t]
        if panoramic:
            for o in range(0, x, step):
                cols = (np.arange(x) + o) % x  # view column c against template column c + o
                err = np.abs(view - tmpl[:, cols]).sum() / (x * y)
                if err < best[0]:
                    best = (err, t, o)
        else:
            w = x - 2 * shift
            for o in range(0, 2 * shift + 1, step):
                err = np.abs(view[:, shift : shift + w] - tmpl[:, o : o + w]).sum() / (w * y)
                if err < best[0]:
                    best = (err, t, o)
    return best[1], best[2], best[0]


def make_lv(y, x, *, panoramic, shift=2, step=1, dtype=torch.float64, **kw) -> LocalView:
    p = LocalViewParams(
        template_x_size=x, template_y_size=y, vt_panoramic=panoramic,
        vt_shift_match=shift, vt_step_match=step, **kw,
    )  # fmt: skip
    return LocalView(p, dtype=dtype)


def smooth_bank(rng: np.random.Generator, n: int, y: int, x: int) -> np.ndarray:
    """Templates with image-like spatial correlation (so the bounds are exercised)."""
    a = rng.random((n, y, x))
    a = (a + np.roll(a, 1, -1) + np.roll(a, -1, -1)) / 3
    a[:, 1:] = (a[:, 1:] + a[:, :-1]) / 2
    return a


# -------------------------------------------------------------------- matching

CASES = [
    # (panoramic, y, x, shift, step, n templates)
    (True, 5, 13, 0, 1, 1),
    (True, 4, 12, 0, 2, 2),
    (True, 6, 16, 0, 3, 500),
    (True, 7, 15, 0, 1, 500),
    (False, 5, 13, 3, 1, 1),
    (False, 4, 12, 2, 2, 2),
    (False, 6, 16, 4, 3, 500),
    (False, 7, 15, 5, 2, 500),
]


@pytest.mark.parametrize(("panoramic", "y", "x", "shift", "step", "n"), CASES)
def test_match_equals_brute_force(panoramic, y, x, shift, step, n):
    rng = np.random.default_rng(n * 100 + x + step)
    bank = smooth_bank(rng, n, y, x)
    lv = make_lv(y, x, panoramic=panoramic, shift=shift, step=step)
    lv.add_templates(bank)
    views = [rng.random((y, x))]  # a novel view
    for _ in range(3):  # views close to stored templates, shifted and noisy
        t = bank[rng.integers(n)]
        views.append(
            np.clip(np.roll(t, int(rng.integers(x)), -1) + 0.05 * rng.random((y, x)), 0, 1)
        )
        views.append(np.clip(t + 0.02 * rng.standard_normal((y, x)), 0, 1))
    for v in views:
        want = brute_force(bank, v, panoramic, shift, step)
        got = lv.match(torch.from_numpy(v))
        assert got[:2] == want[:2]
        assert got[2] == pytest.approx(want[2], abs=1e-9)
        # the full error table agrees with the loop too
        errs = lv.errors(torch.from_numpy(v))
        assert float(errs.min()) == pytest.approx(want[2], abs=1e-9)
        # pruning off gives the same answer
        lv.prune = False
        assert lv.match(torch.from_numpy(v))[:2] == want[:2]
        lv.prune = True


@settings(max_examples=25, deadline=None)
@given(
    panoramic=st.booleans(),
    y=st.integers(1, 6),
    x=st.integers(3, 17),
    shift=st.integers(0, 4),
    step=st.integers(1, 5),
    n=st.integers(1, 40),
    seed=st.integers(0, 2**16),
    quantised=st.booleans(),
)
@example(panoramic=True, y=2, x=3, shift=0, step=1, n=5, seed=0, quantised=False)  # a tie
def test_match_equals_brute_force_random_shapes(panoramic, y, x, shift, step, n, seed, quantised):
    shift = min(shift, (x - 1) // 2)  # normal mode needs X > 2 * shift
    rng = np.random.default_rng(seed)
    bank = smooth_bank(rng, n, y, x)
    if quantised:  # coarse values: many exact ties between templates and offsets
        bank = np.round(bank * 4) / 4
    lv = make_lv(y, x, panoramic=panoramic, shift=shift, step=step)
    lv.add_templates(bank)
    v = bank[rng.integers(n)] if quantised else rng.random((y, x))
    want = brute_force(bank, v, panoramic, shift, step)
    got = lv.match(v)
    assert got[2] == pytest.approx(want[2], abs=1e-9)
    if got[:2] != want[:2]:
        # the same error to rounding (random values can tie to the last bit, e.g. two
        # offsets of a 3-column panorama): the winner may then differ; exact ties are
        # decided as brute force does (quantised examples, test_ties_go_to_lowest_...)
        assert not quantised
        offsets = lv.offsets.tolist()
        got_err = float(lv.errors(v, [got[0]])[0, offsets.index(got[1])])
        assert abs(got_err - want[2]) < 1e-12


@pytest.mark.parametrize("panoramic", [True, False])
def test_float32_matches_float64_reference(panoramic):
    rng = np.random.default_rng(7)
    y, x = 8, 20
    bank = smooth_bank(rng, 300, y, x)
    lv = make_lv(y, x, panoramic=panoramic, shift=3, dtype=torch.float32)
    lv.add_templates(bank)
    for i in range(6):
        v = np.clip(np.roll(bank[i * 40], 2 * i, -1) + 0.03 * rng.standard_normal((y, x)), 0, 1)
        tid, off, err = lv.match(v.astype(np.float32))
        wid, woff, werr = brute_force(bank.astype(np.float32).astype(np.float64),
                                      v.astype(np.float32).astype(np.float64),
                                      panoramic, 3, 1)  # fmt: skip
        assert err == pytest.approx(werr, abs=1e-6)
        # same winner, unless two candidates tie within float32 rounding
        if (tid, off) != (wid, woff):
            assert abs(lv.errors(v.astype(np.float32), [tid])[0].min() - werr) < 1e-6


@pytest.mark.parametrize("panoramic", [True, False])
def test_ties_go_to_lowest_id_then_lowest_offset(panoramic):
    # dyadic values: every sum is exact, so duplicated templates tie exactly
    rng = np.random.default_rng(3)
    y, x = 4, 16
    base = rng.integers(0, 256, (5, y, x)) / 256.0
    bank = np.concatenate([base, base[[2, 2]]])  # ids 5 and 6 duplicate id 2
    lv = make_lv(y, x, panoramic=panoramic, shift=2)
    lv.add_templates(bank)
    view = base[2].copy()
    tid, off, err = lv.match(view)
    assert (tid, err) == (2, 0.0)
    assert (tid, off) == brute_force(bank, view, panoramic, 2, 1)[:2]
    # a constant-per-row template matches every panoramic offset equally: lowest offset wins
    flat = np.repeat(rng.random((y, 1)), x, axis=1)
    lv2 = make_lv(y, x, panoramic=True)
    lv2.add_templates(np.stack([flat, flat]))
    assert lv2.match(flat)[:2] == (0, 0)


@pytest.mark.parametrize("panoramic", [True, False])
def test_threshold_search_is_exact_below_and_a_bound_above(panoramic):
    rng = np.random.default_rng(11)
    y, x = 6, 16
    bank = smooth_bank(rng, 200, y, x)
    lv = make_lv(y, x, panoramic=panoramic, shift=3)
    lv.add_templates(bank)
    for i in range(8):
        v = rng.random((y, x)) if i % 2 else np.clip(bank[i * 20] + 0.01 * rng.random((y, x)), 0, 1)
        want = brute_force(bank, v, panoramic, 3, 1)
        for thr in (0.02, 0.05, 0.2):
            tid, off, err = lv.match(v, threshold=thr)
            if want[2] <= thr:
                assert (tid, off) == want[:2] and err == pytest.approx(want[2], abs=1e-9)
            else:
                assert tid == -1 and thr < err <= want[2] + 1e-9


def test_panoramic_rotation_gives_offset_and_angle_across_the_wrap():
    rng = np.random.default_rng(5)
    y, x = 6, 24
    tmpl = smooth_bank(rng, 1, y, x)[0]
    lv = make_lv(y, x, panoramic=True, step=1, vt_match_threshold=0.01)
    assert lv.process(tmpl).is_new
    for k in (0, 1, 5, 11, 12, 13, 20, 23):
        view = np.roll(tmpl, -k, axis=-1)  # the camera turned by k columns
        m = lv.process(view)
        assert not m.is_new and m.template_id == 0 and m.offset == k and m.error == 0.0
        want = k / x * 2 * math.pi
        want = want - 2 * math.pi if want > math.pi else want
        assert m.relative_rad == pytest.approx(want)
        assert -math.pi < m.relative_rad <= math.pi
    # with a step, a rotation that is a multiple of it is found exactly
    lv3 = make_lv(y, x, panoramic=True, step=3)
    lv3.add_templates(tmpl[None])
    assert lv3.match(np.roll(tmpl, -21, axis=-1))[1:] == (21, 0.0)


def test_normal_mode_shift_gives_offset_and_zero_angle():
    rng = np.random.default_rng(6)
    y, x, s = 5, 20, 4
    tmpl = smooth_bank(rng, 1, y, x)[0]
    lv = make_lv(y, x, panoramic=False, shift=s, step=1, vt_match_threshold=0.01)
    lv.add_templates(tmpl[None])
    for k in range(-s, s + 1):
        view = np.roll(tmpl, k, axis=-1)  # content moved right by k columns
        m = lv.process(view)
        assert (m.template_id, m.offset, m.relative_rad, m.is_new) == (0, s - k, 0.0, False)
        assert m.error == pytest.approx(0.0, abs=1e-12)


def test_brightness_change_absorbed_new_scene_learnt_same_scene_not():
    rng = np.random.default_rng(8)
    p = LocalViewParams(
        template_x_size=32, template_y_size=8, vt_normalisation=0.4, vt_match_threshold=0.03,
        vt_shift_match=2, vt_step_match=1,
    )  # fmt: skip
    scene = np.kron(rng.random((8, 32)), np.ones((4, 4))) * 0.5  # 128x32 image in [0, 0.5]
    img = (scene * 255).astype(np.uint8)
    lv = LocalView(p)
    first = lv.process(img, frame_index=0)
    assert first.is_new and first.template_id == 0 and first.error == math.inf
    darker = lv.process((img * 0.7).astype(np.uint8), frame_index=1)
    assert not darker.is_new and darker.template_id == 0 and darker.error < 0.01
    # without normalisation the same change is a different view
    plain = LocalView(p.replace(vt_normalisation=0.0))
    plain.process(img)
    assert plain.process((img * 0.7).astype(np.uint8)).is_new
    other = (np.kron(rng.random((8, 32)), np.ones((4, 4))) * 255).astype(np.uint8)
    new = lv.process(other, frame_index=2)
    assert new.is_new and new.template_id == 1 and new.error > p.vt_match_threshold
    again = lv.process(img, frame_index=3)
    assert not again.is_new and again.template_id == 0
    assert len(lv) == 2 and lv.bank.frames.tolist() == [0, 2]
    assert lv.current_id == 0 and lv.previous_id == 1


def test_frames_are_accepted_and_a_changed_image_size_is_an_error():
    rng = np.random.default_rng(14)
    p = LocalViewParams(template_x_size=16, template_y_size=4, vt_shift_match=2, vt_step_match=1)
    img = rng.integers(0, 256, (16, 64)).astype(np.uint8)
    lv = LocalView(p)
    m = lv.process(Frame(index=5, t=0.5, image=img), frame_index=5)
    assert m.is_new and lv.bank.frames.tolist() == [5] and lv.image_shape == (16, 64)
    assert lv.process(Frame(index=6, t=0.6, image=img)).template_id == 0
    with pytest.raises(InputError, match=r"\(16, 64\)"):
        lv.process(rng.integers(0, 256, (16, 80)).astype(np.uint8))
    with pytest.raises(InputError, match="None"):
        LocalView(p).process(Frame(index=0, t=0.0, image=None))
    restored = LocalView(p)
    restored.set_state(lv.get_state())
    assert restored.image_shape == (16, 64)


def test_exact_errors_option_reports_the_true_minimum_for_novel_views():
    rng = np.random.default_rng(9)
    y, x = 6, 16
    bank = smooth_bank(rng, 50, y, x)
    params = LocalViewParams(template_x_size=x, template_y_size=y, vt_panoramic=True,
                             vt_step_match=1, vt_match_threshold=0.01)  # fmt: skip
    fast, exact = (
        LocalView(params, dtype=torch.float64),
        LocalView(params, dtype=torch.float64, exact_errors=True),
    )
    fast.add_templates(bank)
    exact.add_templates(bank)
    v = rng.random((y, x))
    want = brute_force(bank, v, True, 0, 1)[2]
    a, b = fast.process(v), exact.process(v)
    assert a.is_new and b.is_new and a.template_id == b.template_id == 50
    assert b.error == pytest.approx(want, abs=1e-9)
    assert params.vt_match_threshold < a.error <= want + 1e-9


def test_bank_grows_by_doubling_without_changing_results():
    rng = np.random.default_rng(10)
    y, x = 5, 12
    bank = smooth_bank(rng, 300, y, x)
    grown = make_lv(y, x, panoramic=True)
    grown.bank = TemplateBank(
        y, x, capacity=1, summaries=grown.matcher.summarise,
        summary_shapes=grown.matcher.make_bank(dtype=torch.float64, device=None).summary_shapes,
        dtype=torch.float64,
    )  # fmt: skip
    caps = []
    for t in bank:
        grown.add_templates(t[None])
        caps.append(grown.bank.capacity)
    assert sorted(set(caps)) == [2**i for i in range(10)]  # 1, 2, 4, ..., 512: doubling
    at_once = make_lv(y, x, panoramic=True)
    at_once.add_templates(bank)
    assert torch.equal(grown.templates, at_once.templates)
    assert torch.allclose(grown.bank.means, torch.from_numpy(bank.mean((1, 2))))
    for i in range(5):
        v = np.clip(np.roll(bank[i * 50], i, -1) + 0.02 * rng.random((y, x)), 0, 1)
        assert (
            grown.match(v)
            == at_once.match(v)
            == (*brute_force(bank, v, True, 0, 1)[:2], pytest.approx(at_once.match(v)[2]))
        )


def test_bad_configuration_and_templates_are_clear_errors():
    with pytest.raises(ConfigError, match="vt_shift_match"):
        LocalView(LocalViewParams(template_x_size=10, template_y_size=2, vt_shift_match=5))
    lv = make_lv(3, 8, panoramic=True)
    with pytest.raises(InputError, match="shape"):
        lv.match(np.zeros((3, 9)))
    with pytest.raises(InputError, match="NaN"):
        lv.add_templates(np.full((1, 3, 8), np.nan))
    assert lv.match(np.zeros((3, 8))) == (-1, 0, math.inf)


# ----------------------------------------------------------------- state, merges


def test_state_round_trip_and_add_templates():
    rng = np.random.default_rng(12)
    cfg = load_config("new_college_openratslam")  # panoramic, patch normalisation
    lv = LocalView(cfg.local_view)
    frames = [rng.integers(0, 256, (40, 240)).astype(np.uint8) for _ in range(6)]
    for i, f in enumerate(frames):
        lv.process(f, frame_index=10 + i)
    state = lv.get_state()
    assert all(isinstance(v, (np.ndarray, int, str)) for v in state.values())
    other = LocalView(cfg.local_view)
    other.set_state(state)
    assert torch.equal(other.templates, lv.templates) and other.current_id == lv.current_id
    assert other.bank.frames.tolist() == lv.bank.frames.tolist()
    probe = lv.preprocess(frames[3])
    assert other.match(probe) == lv.match(probe)
    ids = other.add_templates(lv.templates.numpy()[:2])
    assert list(ids) == [len(lv), len(lv) + 1]
    assert other.match(lv.templates[1])[0] == 1  # lowest id wins over the appended copy
    bad = dict(state, templates=state["templates"][:, :, :-1])
    with pytest.raises(MapFormatError):
        LocalView(cfg.local_view).set_state(bad)
    with pytest.raises(MapFormatError, match="version"):
        LocalView(cfg.local_view).set_state(dict(state, version=99))


def test_a_shared_state_is_a_read_only_view_of_the_rows_equal_to_the_copy():
    """``get_state(share=True)`` (a checkpoint's) holds the same templates as the copy,
    without copying them, and cannot be written through."""
    rng = np.random.default_rng(14)
    lv = LocalView(load_config("irat").local_view)
    for i in range(5):
        lv.process(rng.integers(0, 256, (120, 160)).astype(np.uint8), frame_index=i)
    copied, shared = lv.get_state(), lv.get_state(share=True)
    assert copied.keys() == shared.keys()
    for k, v in copied.items():
        assert np.array_equal(np.asarray(v), np.asarray(shared[k])), k
    rows = lv.bank.array("data")
    assert np.shares_memory(shared["templates"], rows)
    assert not np.shares_memory(copied["templates"], rows)
    with pytest.raises(ValueError, match="read-only"):
        shared["templates"][0, 0, 0] = 1.0


# --------------------------------------------------------------- generic sensors


def test_feature_view_on_circular_scans_and_frames():
    rng = np.random.default_rng(13)
    p = LocalViewParams(vt_panoramic=True, vt_step_match=1, vt_match_threshold=0.05)
    fv = FeatureView(p, key="laser_front", scale=0.1)
    scan = rng.random(90) * 10  # metres
    frame = Frame(index=0, t=0.0, image=None, scans={"laser_front": scan})
    assert fv.process(frame).is_new and fv.template_shape == (1, 90)
    turned = Frame(index=1, t=0.1, image=None, scans={"laser_front": np.roll(scan, -30)})
    m = fv.process(turned)
    assert (m.template_id, m.offset, m.is_new) == (0, 30, False)
    assert m.relative_rad == pytest.approx(30 / 90 * 2 * math.pi)
    assert fv.process(rng.random(90) * 10).is_new
    with pytest.raises(InputError, match="same size"):
        fv.process(np.zeros(80))
    with pytest.raises(InputError, match="laser_rear"):
        FeatureView(p, key="laser_rear").process(frame)
    with pytest.raises(InputError, match="NaN"):
        fv.process(np.full(90, np.nan))
    # 2D features match like images, exactly as the brute-force loop
    fv2 = FeatureView(LocalViewParams(vt_shift_match=2, vt_step_match=1), dtype=torch.float64)
    bank = smooth_bank(rng, 20, 3, 11)
    fv2.add_templates(bank)
    v = np.clip(bank[7] + 0.01 * rng.random((3, 11)), 0, 1)
    assert fv2.match(v)[:2] == brute_force(bank, v, False, 2, 1)[:2]


def test_registered_in_local_views():
    assert LOCAL_VIEWS.get("ratslam") is LocalView
    assert LOCAL_VIEWS.get("features") is FeatureView
    lv = LOCAL_VIEWS.get("ratslam")(load_config("irat").local_view, dtype=torch.float32)
    assert lv.templates.shape == (0, 30, 50)
    assert lv.memory_bytes() >= lv.bank.capacity * 30 * 50 * 4


@pytest.mark.parametrize("panoramic", [True, False])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_compiled_screening_gives_the_torch_search_bit_for_bit(panoramic, dtype):
    """The compiled stages (numba, CPU) only skip pairs: every answer, error included,
    is the one the torch chunks give, also with near-ties and thresholds."""
    rng = np.random.default_rng(21)
    y, x = 8, 24
    bank = smooth_bank(rng, 400, y, x)
    bank[200:260] = np.clip(bank[100:160] + 1e-4 * rng.standard_normal((60, y, x)), 0, 1)
    lv = make_lv(y, x, panoramic=panoramic, shift=4, dtype=dtype)
    lv.add_templates(bank)
    assert lv.matcher is not None and lv.matcher.compiled  # the default on the CPU
    views = [rng.random((y, x))]
    for i in range(12):
        t = bank[int(rng.integers(400))]
        views.append(np.clip(np.roll(t, i % 5 - 2, -1) + 0.01 * rng.random((y, x)), 0, 1))
    for v in views:
        vt = torch.from_numpy(v).to(dtype)
        for thr in (None, 0.01, 0.05):
            lv.matcher.compiled = True
            fast = lv.matcher.search(lv.bank, vt, hint=3, threshold=thr)
            lv.matcher.compiled = False
            slow = lv.matcher.search(lv.bank, vt, hint=3, threshold=thr)
            assert fast[:2] == slow[:2]
            if fast[0] >= 0:
                assert fast[2] == slow[2]  # the same exact kernel decided both
            else:  # both lower bounds of the best error, above the threshold
                best = float(lv.errors(vt).min())
                assert thr is not None and thr < fast[2] <= best + 1e-6
    lv.matcher.compiled = True


@pytest.mark.parametrize(
    ("x", "shift", "step"), [(1, 0, 1), (2, 0, 1), (3, 1, 1), (9, 4, 3), (10, 2, 2)]
)
def test_compiled_search_on_narrow_windows(x, shift, step):
    """Windows of one or two columns (no column pair, or one) and odd offsets."""
    rng = np.random.default_rng(x * 10 + shift)
    y = 3
    bank = smooth_bank(rng, 30, y, x) if x > 2 else rng.random((30, y, x))
    lv = make_lv(y, x, panoramic=False, shift=shift, step=step)
    lv.add_templates(bank)
    for i in range(5):
        v = np.clip(bank[i * 5] + 0.01 * rng.random((y, x)), 0, 1) if i else rng.random((y, x))
        want = brute_force(bank, v, False, shift, step)
        got = lv.match(v)
        assert got[:2] == want[:2] and got[2] == pytest.approx(want[2], abs=1e-12)
