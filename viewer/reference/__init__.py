"""The float64 NumPy reference tracer, written from the scene-format
specification alone, independently of the GPU shader, which it checks.

Its floor imports only ``scene`` and ``base`` (never ``gpu``: the two
tracers must not share a bug by sharing code).  One job a module, each
importing only those below it:

* ``refine``: ``render_reference_refined``, more samples where a pixel needs
  them, and its process pool.
* ``trace``: the tracer proper (the ray tree, shading, shadows,
  ``render_reference``, ``trace``); the usual entry point.
* ``surfaces``: where rays meet the scene (next interaction, shadow
  transmittance, ``first_hit``, ``medium_at``) and the epsilon ``EPS_REL``.
* ``camera``: the pinhole camera's primary rays (``camera_rays``,
  ``pixel_rays``).
* ``primitives``: each object's surface crossings and point containment
  (``contains``, ``rotation_matrix``).
* ``optics``: Fresnel, refraction, Beer–Lambert absorption.
* ``sky``: what an escaping ray sees (``sky_radiance``).
* ``vectors``: row-wise dot product and normalisation.

This file imports none of them, so that importing one module does not
load the rest.
"""
