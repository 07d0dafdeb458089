"""The applications built on warptex: the command line and what it needs.

- :mod:`.cli`: ``warptex render | demo | fit`` (also ``python -m warptex``);
- :mod:`.render`: the main job, a textured, lit render of the procedural terrain or a mesh;
- :mod:`.demo`: filters and address modes side by side on a ground plane;
- :mod:`.fit_demo` and :mod:`.fit_report`: ``warptex fit``, recovering splat maps and tiling;
- :mod:`.terrain` and :mod:`.terrain_material`: the procedural terrain mesh and its layers;
- :mod:`.shade` and :mod:`.plot`: Lambert previews, labelled panels, line charts.

These use the library (``warptex``); the library never imports them.
"""
