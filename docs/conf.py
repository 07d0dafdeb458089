"""Sphinx configuration of the warptex docs: Markdown pages (MyST), the furo theme, and the API
reference from the docstrings (autodoc, Google-style sections by napoleon).

Build: ``sphinx-build -W -b html docs docs/_build/html`` (warnings are errors, as in CI).
"""

import os
import sys

sys.path.insert(0, os.path.abspath(".."))  # a checkout documents itself, installed or not

project = "warptex"
author = "the warptex authors"
copyright = "2026, the warptex authors"  # noqa: A001 (Sphinx's name)

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build"]
root_doc = "index"

myst_heading_anchors = 3  # [text](page.md#a-heading) links
myst_enable_extensions = ["colon_fence"]

autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the signatures say them; the docstrings say what they mean
autodoc_default_options = {"members": True, "undoc-members": False}
autodoc_mock_imports = ["torch"]  # the PyTorch bridge's reference builds without PyTorch
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # a dataclass's "Attributes:" as fields of its entry, not a second description of its members

html_theme = "furo"
html_title = "warptex"
