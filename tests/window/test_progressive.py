"""The viewer's progressive renderer, offscreen (no window): accumulation in
bands equals `glassray render`, previews, the display encoding, resizing."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import make_scene
from viewer.base.imageio import to_display8
from viewer.window.progressive import Progressive
from viewer.gpu.renderer import Renderer

DOC = {
    "camera": {"position": [0.0, 1.5, 4.0], "target": [0.0, 0.6, 0.0]},
    "render": {"samples": 3},
    "lights": [{"position": [2.0, 4.0, 3.0]}],
    "materials": {"floor": {"checker": {"color": [0.2, 0.2, 0.2], "size": 0.5}},
                  "red": {"color": [0.9, 0.2, 0.1], "specular": 0.4},
                  "glass": {"ambient": 0, "diffuse": 0, "transparency": 1, "ior": 1.5}},
    "objects": [{"type": "plane", "material": "floor"},
                {"type": "sphere", "center": [-0.6, 0.5, 0], "radius": 0.5, "material": "red"},
                {"type": "sphere", "center": [0.6, 0.5, 0], "radius": 0.5, "material": "glass"}],
}


def first_sample(r, w, h):
    """What the first pass of an accumulation of the scene's samples holds:
    sample 0 as Renderer.render takes it for that many samples (3 here, a
    checkered floor: a footprint sample, the same as render's)."""
    assert r.takes_footprint(r.scene.render.samples)
    return r.render(w, h, 1, footprint=True)


@pytest.fixture
def setup(gl):
    scene = make_scene(DOC, "progressive")
    r = Renderer(gl, scene)
    p = Progressive(gl, r)
    yield gl, scene, r, p
    p.release()
    r.release()


def test_accumulation_in_bands_equals_the_offscreen_render(setup):
    gl, scene, r, p = setup
    w, h = 61, 37  # odd sizes: bands do not divide them
    p.resize(w, h)
    p.cost_per_px = 1e-3  # pretend it is slow: bands of a row or two per call
    calls = 0
    while not p.done:
        p.accumulate(budget_ms=0.05)
        calls += 1
        if p.passes_done == 1 and p.next_row == 0 and calls < 1000:
            # after the first complete sample every pixel has exactly one
            one = p.image()
            assert np.array_equal(one, first_sample(r, w, h))
    assert calls > 3 * 2  # it really went band by band
    assert p.passes_done == 3
    expected = r.render(w, h, 3)
    assert np.array_equal(p.image(), expected)
    assert p.accumulate() == 0.0  # done: no more work


def test_partial_pass_divides_each_pixel_by_its_own_count(setup):
    gl, scene, r, p = setup
    w, h = 40, 30
    p.resize(w, h)
    p.finish_pass()
    assert p.passes_done == 1
    p.cost_per_px = 1.0  # one row per call
    p.accumulate(budget_ms=0.01)
    assert p.passes_done == 1 and 0 < p.next_row < h
    img = p.image()
    assert np.array_equal(img[p.next_row:], first_sample(r, w, h)[p.next_row:])  # rows with one sample


def test_preview_scale_follows_the_measured_cost(setup):
    gl, scene, r, p = setup
    p.resize(200, 100)
    p.cost_per_px = 1e-6  # 20000 px would take 20 ms
    assert p.preview_scale(20.0) == pytest.approx(1.0)
    assert p.preview_scale(5.0) == pytest.approx(0.5)
    p.cost_per_px = 1.0
    assert p.preview_scale(5.0) == pytest.approx(1 / 32)  # the floor
    p.render_preview(10.0)
    pw, ph = p.preview_size
    assert (pw, ph) == (round(200 * p.preview_scale(10.0)), round(100 * p.preview_scale(10.0))) or pw >= 1


def test_display_shows_the_encoded_image_and_the_preview_until_samples_land(setup):
    gl, scene, r, p = setup
    w, h = 48, 27
    p.resize(w, h)
    out = gl.simple_framebuffer((w, h), components=4)
    # nothing traced and no preview yet: black
    p.display(out, (0, 0, w, h))
    assert not np.frombuffer(out.read(components=3), np.uint8).any()
    # a full-resolution preview is shown where there is no sample yet
    p.cost_per_px = 1e-12
    p.render_preview(1000.0)
    assert p.preview_size == (w, h)
    p.display(out, (0, 0, w, h))
    shown = np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    assert np.abs(shown.astype(int) - to_display8(r.render(w, h, 1)).astype(int)).max() <= 1
    # accumulated samples: the spec's display encoding of the mean
    while not p.done:
        p.accumulate(1000.0)
    p.display(out, (0, 0, w, h))
    shown = np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    expected = to_display8(r.render(w, h, 3))
    assert np.abs(shown.astype(int) - expected.astype(int)).max() <= 1
    release_target(out)


def test_resize_and_zero_size(setup):
    gl, scene, r, p = setup
    p.resize(30, 20)
    p.finish_pass()
    p.resize(0, 0)  # minimised
    assert p.size == (0, 0) and p.accum_tex is None
    assert p.accumulate() == 0.0 and p.render_preview() == 0.0
    p.finish_pass()
    p.resize(25, 15)
    assert p.passes_done == 0 and p.accum_tex.size == (25, 15)
    p.finish_pass()
    assert p.image().shape == (15, 25, 3)


def test_scene_changes_restart_the_accumulation(setup):
    gl, scene, r, p = setup
    p.resize(20, 12)
    while not p.done:
        p.accumulate(1000.0)
    scene.lights[0].position = (-2.0, 4.0, 3.0)
    r.set_scene(scene)
    p.restart()
    assert p.passes_done == 0 and not p.image().any()
    p.finish_pass()
    assert np.array_equal(p.image(), first_sample(r, 20, 12))


# ---------------------------------------------------------------- adaptive accumulation

#: A plain floor (no checker) and a matte ball, seen from above, under a
#: constant sky, lit from the camera (its shadow hides behind it):
#: everything away from the ball's outline is flat.
FLAT = {
    "camera": {"position": [0.0, 4.0, 2.5], "target": [0.0, 0.0, 0.0], "fov": 50},
    "render": {"samples": 8, "max_depth": 3},
    "sky": {"type": "color", "color": [0.5, 0.6, 0.8]},
    "lights": [{"position": [0.0, 4.0, 2.5]}],
    "materials": {"floor": {"color": [0.6, 0.6, 0.6]}, "red": {"color": [0.9, 0.2, 0.1], "specular": 0}},
    "objects": [{"type": "plane", "material": "floor"},
                {"type": "sphere", "center": [0.0, 0.4, 0], "radius": 0.4, "material": "red"}],
}


def accum_mean(p: Progressive) -> tuple[np.ndarray, np.ndarray]:
    """What the display pass divides: accum_tex read back, plus, while an
    adaptive round is in flight, what the display adds to it (the round's
    list target at each pixel's texel), top row first, as (sum / count,
    count)."""
    w, h = p.size
    acc = np.frombuffer(p.accum_tex.read(), np.float32).reshape(h * w, 4).copy()
    if p._showing_round:
        sums_tex = p._overlay[1]
        sums = np.frombuffer(sums_tex.read(), np.float32).reshape(-1, 4)
        k = np.frombuffer(p._slot_tex.read(), np.int32)
        acc[k >= 0] += sums[k[k >= 0]]
    acc = acc.reshape(h, w, 4)[::-1]
    count = acc[..., 3]
    return acc[..., :3] / np.maximum(count, 1)[..., None], count


def release_target(out) -> None:
    """Release a simple_framebuffer and its renderbuffers (Framebuffer.release
    leaves its attachments: two renderbuffers leaked per call, which
    _gl_counts then counted wherever their names fell in its range)."""
    for attachment in (*out.color_attachments, out.depth_attachment):
        if attachment is not None:
            attachment.release()
    out.release()


def shown8(gl, p: Progressive) -> np.ndarray:
    """The display pass's 8-bit output (H, W, 3) int, top row first."""
    w, h = p.size
    out = gl.simple_framebuffer((w, h), components=4)
    try:
        p.display(out, (0, 0, w, h))
        return np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1].astype(int)
    finally:
        release_target(out)


def run_adaptive(p: Progressive, budget_ms: float = 1e-3, limit: int = 10000) -> list[float]:
    """Accumulate until done with a budget so small that every call takes
    exactly one step; return mean_spp after each call."""
    means = []
    while not p.done:
        assert len(means) < limit
        p.accumulate(budget_ms=budget_ms)
        means.append(p.mean_spp)
    return means


def sized(setup, w: int, h: int, samples: int) -> None:
    """The adaptive_setup's scene at `samples` and its Progressive at w x h."""
    _, scene, r, p = setup
    scene.render.samples = samples
    r.set_scene(scene)
    p.resize(w, h)


@pytest.fixture
def adaptive_setup(gl):
    scene = make_scene(DOC, "adaptive")
    r = Renderer(gl, scene)
    p = Progressive(gl, r, adaptive=True, seed=3)
    yield gl, scene, r, p
    p.release()
    r.release()


def test_adaptive_accumulation_equals_the_offscreen_adaptive_render(adaptive_setup):
    from viewer.adaptive.render import render_adaptive

    gl, scene, r, p = adaptive_setup
    w, h = 61, 37
    sized(adaptive_setup, w, h, 6)
    assert p.adaptive and not p.done and p.mean_spp == 0.0
    means = run_adaptive(p)
    job = p.job
    # one step per accumulate(): a draw call, the bookkeeping between passes
    # (a step of its own), or, last, the end
    assert len(means) == job.steps_done > 3
    assert 3 < job.draws_done < job.steps_done
    expected = render_adaptive(r, w, h, 6, seed=3)
    assert np.array_equal(job.spp, expected.spp)
    assert expected.spp.max() > 6 and expected.spp.min() == 1  # really adaptive
    np.testing.assert_allclose(p.image(), expected.image, rtol=1e-6, atol=1e-7)
    # what the display pass shows: the same sums, uploaded rows bottom first
    mean, count = accum_mean(p)
    assert np.array_equal(count, expected.spp)
    np.testing.assert_allclose(mean, expected.image, rtol=1e-5, atol=1e-6)
    out = gl.simple_framebuffer((w, h), components=4)
    p.display(out, (0, 0, w, h))
    shown = np.frombuffer(out.read(components=3), np.uint8).reshape(h, w, 3)[::-1]
    release_target(out)
    assert np.abs(shown.astype(int) - to_display8(expected.image).astype(int)).max() <= 1
    assert p.accumulate() == 0.0  # done: no more work
    # another seed is another picture: the seed really reaches the render
    other = render_adaptive(r, w, h, 6, seed=4)
    assert not np.array_equal(other.image, p.image())


def test_a_round_in_flight_is_shown_as_it_goes(adaptive_setup):
    # A round's samples reach the window draw by draw (the display adds the
    # round's list target on the GPU), not only when the round ends: at
    # every frame the window shows the mean of every sample traced so far
    # (p.image(), merged on the CPU from the job's own sums: another route)
    # and the HUD's mean is the mean of the pixels' counts.
    gl, scene, r, p = adaptive_setup
    w, h = 40, 24
    sized(adaptive_setup, w, h, 16)
    shown_in_rounds, states = 0, []
    while not p.done:
        p.accumulate(budget_ms=1e-3)
        if not p.has_full_sample:
            continue
        image = p.image()
        mean, count = accum_mean(p)
        assert p.mean_spp == pytest.approx(count.mean(), abs=1e-9)
        np.testing.assert_allclose(mean, image, rtol=1e-5, atol=1e-6)
        assert np.abs(shown8(gl, p) - to_display8(image).astype(int)).max() <= 1
        shown_in_rounds += p._showing_round
        states.append(p.mean_spp)
    rounds = len(p.job.rounds)
    # more distinct pictures than passes: rounds are shown part by part
    assert shown_in_rounds > rounds and len(set(states)) > rounds
    drops = [(a, b) for a, b in zip(states, states[1:]) if b < a - 1e-9]
    assert not drops
    assert p.mean_spp == pytest.approx(p.job.spp.mean())


def test_mean_spp_grows_to_at_most_samples_and_flat_regions_keep_one(gl):
    scene = make_scene(FLAT, "flat")
    r = Renderer(gl, scene)
    p = Progressive(gl, r, adaptive=True)
    try:
        w, h = 64, 36
        p.resize(w, h)
        means = run_adaptive(p)
        assert means[0] == 0.0  # the first pass is one draw, still in flight
        assert all(b >= a for a, b in zip(means, means[1:]))
        assert 1 in means and 1.0 < means[-1] <= 8
        assert means[-1] == pytest.approx(p.job.spp.mean())
        spp = p.job.spp
        # flat: farther than 2 px from every pixel whose camera ray hits the ball
        _, obj, _ = r.first_hits(w, h)
        ball = np.pad(obj == 1, 2)
        near = np.zeros((h, w), bool)
        for dy in range(5):
            for dx in range(5):
                near |= ball[dy:dy + h, dx:dx + w]
        assert near.sum() < 0.2 * w * h
        assert (spp[~near] == 1).all()
        # the ball's outline got more than the mean
        edge = near & ~(obj == 1)
        assert spp[edge].max() > 8
    finally:
        p.release()
        r.release()


def _gl_counts(gl) -> dict[str, int]:
    """GL objects of each kind in the current (EGL) context: glIs* over the
    names up to a little past the newest one."""
    import ctypes

    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    proto = ctypes.CFUNCTYPE(ctypes.c_ubyte, ctypes.c_uint)
    probes = [gl.buffer(reserve=4), gl.texture((1, 1), 4)]
    probes.append(gl.framebuffer(color_attachments=[probes[1]]))
    upper = max(p.glo for p in probes) + 1024
    counts = {}
    try:
        for kind in ("Buffer", "Texture", "Framebuffer", "VertexArray", "Program", "Renderbuffer"):
            addr = egl.eglGetProcAddress(f"glIs{kind}".encode())
            if not addr:
                pytest.skip("no glIs* through eglGetProcAddress")
            fn = proto(addr)
            counts[kind] = sum(1 for name in range(1, upper) if fn(name))
    finally:
        for obj in reversed(probes):
            obj.release()
    return counts


def test_a_restart_releases_the_adaptive_render_and_starts_over(adaptive_setup):
    from viewer.adaptive.render import render_adaptive

    # rounds enough to stop in
    gl, scene, r, p = adaptive_setup
    w, h = 40, 24
    sized(adaptive_setup, w, h, 16)
    run_adaptive(p)  # compiles the adaptive shader variants (kept by the renderer)
    p.restart()
    base = _gl_counts(gl)
    for steps in (1, 2, 3, 1, 2, 3):
        # 1 step: the first pass in flight (its own targets); more: pixel lists
        for _ in range(steps):
            p.accumulate(budget_ms=1e-3)
        assert p.job is not None and not p.done
        old = p.job
        scene.camera.position = (0.1 * steps, 1.5, 4.0)  # the camera moved
        r.set_scene(scene)
        p.restart()
        assert p.job is None and old.done and p.mean_spp == 0.0 and not p.started
        assert old.sampler._list_tex is None and not old.sampler._mrt and old.sampler._offsets_tex is None
        assert _gl_counts(gl) == base  # nothing of the old render is left
    assert p._uploaded_spent == 0 and not accum_mean(p)[1].any()
    # the new view from the start: the offscreen adaptive render of the new camera
    run_adaptive(p)
    expected = render_adaptive(r, w, h, seed=3)
    assert np.array_equal(p.job.spp, expected.spp)
    np.testing.assert_allclose(p.image(), expected.image, rtol=1e-6, atol=1e-7)
    # a finished render gives its GL objects back at once (the idle viewer keeps its sums only)
    assert _gl_counts(gl) == base
    # a resize starts over too, at the new size
    p.accumulate(budget_ms=1e-3)
    p.resize(30, 20)
    assert p.job is None and not p.done
    run_adaptive(p)
    assert p.job.spp.shape == (20, 30)


def test_adaptive_screenshot_and_switching_modes(adaptive_setup):
    gl, scene, r, p = adaptive_setup
    w, h = 40, 24
    sized(adaptive_setup, w, h, 16)
    # P before anything is traced: the first sample of every pixel (the
    # centre), a footprint sample where the pixel lies on the checker
    p.finish_pass()
    assert p.has_full_sample and p.mean_spp == 1.0 and not p.done
    one = r.render(w, h, 1)
    on_checker = p.job.footprint_mask
    assert 0.2 < on_checker.mean() < 0.9                   # both kinds of pixel are seen
    assert np.array_equal(p.image()[~on_checker], one[~on_checker])
    # there the checker is box-filtered over the pixel: nearer the converged
    # picture than the centre's point sample (RMSE there measured 0.017
    # against 0.084; the shadow edges on the floor are left to samples)
    converged = r.render(w, h, 256, seed=9)
    err = lambda img: float(np.sqrt(np.mean((img - converged)[on_checker] ** 2)))  # noqa: E731
    assert err(p.image()) < 0.5 * err(one)
    assert np.array_equal(accum_mean(p)[1], np.ones((h, w)))
    # a screenshot mid-way is the mean so far, the same as what is shown
    while p.mean_spp == 1.0:
        p.accumulate(budget_ms=1e-3)
    assert not p.done and p._showing_round  # the first round is in flight
    mean, count = accum_mean(p)
    assert count.max() > 1
    np.testing.assert_allclose(p.image(), mean, rtol=1e-5, atol=1e-6)
    assert np.abs(shown8(gl, p) - to_display8(p.image()).astype(int)).max() <= 1
    assert not np.array_equal(p.image(), one)
    p.finish_pass()  # nothing to do: every pixel has a sample
    assert p.mean_spp == pytest.approx(count.mean())
    # switched off: uniform passes from the start, as before
    p.adaptive = False
    assert p.job is None and p.passes_done == 0 and not p.image().any()
    while not p.done:
        p.accumulate(1000.0)
    assert p.mean_spp == 16 and np.array_equal(p.image(), r.render(w, h, 16, seed=3))
    p.adaptive = True
    assert not p.done and p.mean_spp == 0.0
