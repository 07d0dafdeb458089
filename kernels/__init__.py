"""All of warptex's Warp code: ``@wp.func`` building blocks and ``@wp.kernel`` entry points.

This package sees only Warp and its own modules; the public API lives in ``warptex``.
"""
