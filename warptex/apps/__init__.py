"""The applications built on warptex: the command line and what it needs.

- :mod:`.cli`: ``warptex render | demo | fit`` (also ``python -m warptex``);
- :mod:`.render`: the main job, a textured, lit render of the procedural terrain or a mesh;
- :mod:`.demo`: filters and address modes side by side on a ground plane;
- :mod:`.fit_demo` and :mod:`.fit_report`: ``warptex fit``, recovering splat maps and tiling;
- :mod:`.shade`: Lambert previews and labelled panels.

The scenes they share with the benchmarks and tests (the procedural terrain, its layers and
camera) are in :mod:`warptex.scenes`; line charts in :mod:`warptex.plot`.

These use the library (``warptex``); the library never imports them.
"""
