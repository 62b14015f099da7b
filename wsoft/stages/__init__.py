"""Building USD stages in code: the tests' stages, the sweeps' corpora and the bundled stages.

The stage-writing API (from :mod:`wsoft.stages.builders`)::

    from wsoft.stages import add_box, add_camera, add_quad, add_rect_light, make_stage

    stage = make_stage()                                   # in memory, Z-up, /World
    add_quad(stage, "/World/Ground", (0, 0, 0), 5)
    add_box(stage, "/World/Box", (-1, -1, 0), (1, 1, 2))
    add_rect_light(stage, "/World/Light", (0, 0, 4), 1, 1)
    add_camera(stage, "/World/Cam", (0, -6, 5), (0, 0, 0))

The rest of the package, by idea:

* :mod:`~wsoft.stages.mesh` — mesh primitives as arrays (``MeshData``: points, counts, indices);
  :mod:`~wsoft.stages.organic` — swept tubes, creatures and plants;
  :mod:`~wsoft.stages.textures` — cutout textures; :mod:`~wsoft.stages.bake_light` — baked
  per-vertex lighting.
* :mod:`~wsoft.stages.adversarial` — the adversarial corpus (hard and hostile stages, what each
  must give); :mod:`~wsoft.stages.failures`, :mod:`~wsoft.stages.essm_cases`,
  :mod:`~wsoft.stages.ssm_cases`, :mod:`~wsoft.stages.moment_cases` — stages of known failures and
  paper cases (``moment_cases.stacked_plates``: light bleeding under stacked occluders);
  :mod:`~wsoft.stages.omni_cases` — a point light at the centre of a closed box (cube-map cases);
  :mod:`~wsoft.stages.cube_cases` — a ring of posts whose shadows cross cube-face edges, receivers
  spread out to a chosen angle off a light's axis (``wsoft bench cube``);
  :mod:`~wsoft.stages.grazing` — a floor seen at grazing incidence from a point-like light (acne);
  :mod:`~wsoft.stages.pipeline` — the USD pipeline stages (render settings, shadowLink).
* :mod:`~wsoft.stages.scenes` — the generators of the bundled stages;
  ``python -m wsoft.stages.bundled`` (:mod:`~wsoft.stages.bundled`) regenerates them.
"""

from __future__ import annotations

from wsoft.stages.builders import (
    add_box,
    add_camera,
    add_class_root,
    add_cylinder_light,
    add_cutout_material,
    add_instance,
    add_material,
    add_mesh,
    add_point_light,
    add_quad,
    add_rect_light,
    add_sphere_light,
    add_sun,
    bind,
    check_points_down,
    look_at_xform,
    make_stage,
    mark_casters,
    set_custom_bool,
    set_display_color,
    set_doc_attr,
    set_doc_string,
    world_dir,
)

__all__ = ["add_box", "add_camera", "add_class_root", "add_cutout_material", "add_cylinder_light", "add_instance", "add_material",
           "add_mesh", "add_point_light", "add_quad", "add_rect_light", "add_sphere_light", "add_sun", "bind", "check_points_down",
           "look_at_xform", "make_stage", "mark_casters", "set_custom_bool", "set_display_color", "set_doc_attr",
           "set_doc_string", "world_dir"]
