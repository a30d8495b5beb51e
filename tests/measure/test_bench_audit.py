"""Audit of what `glassray bench` measures: each check is against values
computed here independently of viewer.bench, never against its output."""

from __future__ import annotations

import numpy as np

from viewer.measure import bench


def test_timed_renders_do_not_remake_the_render_target(gl, monkeypatch):
    """A resolution-scaled setting shared its Renderer with the full-size
    ones; a Renderer keeps its offscreen target (and footprint mask) for
    the last size only, so the timed render of every setting drawn after
    one of another size re-made them, inside the clock (preset:preview at
    320x180: 14.1 ms CPU against 11.9 ms).  No timed render may allocate a
    target of a new size."""
    import viewer.gpu.renderer as renderer_module
    from viewer.scene.load import load_scene

    scene = load_scene("glass-sphere")
    r = scene.render
    base = bench.Setting("default", r.max_depth, 2, r.min_weight)
    settings = [base, bench.Setting("scale=0.5", r.max_depth, 2, r.min_weight, scale=0.5),
                bench.Setting("min_weight=0.01", r.max_depth, 2, 0.01)]
    timing = [False]
    remade = []
    real_target = renderer_module.Renderer._target

    def target(self, width, height):
        if timing[0] and (self._fbo is None or tuple(self._fbo.size) != (width, height)):
            remade.append((width, height))
        return real_target(self, width, height)

    real_timed = bench._timed_render

    def timed(*a, **k):
        timing[0] = True
        try:
            return real_timed(*a, **k)
        finally:
            timing[0] = False

    monkeypatch.setattr(renderer_module.Renderer, "_target", target)
    monkeypatch.setattr(bench, "_timed_render", timed)
    w, h = 16, 10
    results = bench.bench_scene(gl, scene, "glass-sphere", settings, w, h, 2, np.zeros((h, w, 3)))
    assert [(x.width, x.height) for x in results] == [(16, 10), (8, 5), (16, 10)]
    assert all(len(x.times) == 2 for x in results)
    assert remade == []


def _screen_coords(scene, width, height):
    """(H, W, 3): the screen position (x, y, 0) of each pixel centre's
    camera ray, from the float64 reference tracer's camera."""
    from viewer.reference.camera import _camera_basis, camera_rays

    _, f, right, up, _ = _camera_basis(scene)
    _, d = camera_rays(scene, width, height)
    depth = d @ f
    return np.stack([d @ right / depth, d @ up / depth, np.zeros_like(depth)], axis=-1)


def test_upscaled_reduced_render_lines_up_with_the_full_size_frame():
    """A resolution-scaled render whose rounded size has another aspect
    (48x27 at scale 0.5: 24x14) spans a narrower part of the scene (the
    vertical field of view is fixed); the upscale stretched it over the
    whole frame, shifting the image by up to 0.4 pixel at the sides.  The
    upscaled screen positions of the small image's pixels must be those of
    the full-size camera (bilinear interpolation is exact on them: they are
    linear in the pixel index), wherever the small image covers the pixel."""
    from viewer.scene.load import load_scene

    scene = load_scene("glass-sphere")
    W, H = 48, 27
    w, h = bench.render_size(bench.Setting("scale=0.5", 8, 1, 1e-3, scale=0.5), W, H)
    assert (w, h) == (24, 14)
    small, full = _screen_coords(scene, w, h), _screen_coords(scene, W, H)
    up = bench.upscale(small, W, H)
    inside = ((full[..., 0] >= small[0, 0, 0]) & (full[..., 0] <= small[0, -1, 0])
              & (full[..., 1] <= small[0, 0, 1]) & (full[..., 1] >= small[-1, 0, 1]))
    assert inside.mean() > 0.8
    np.testing.assert_allclose(up[inside], full[inside], atol=1e-9)
