"""Sphinx configuration of the fdikit documentation.

Why Sphinx + MyST-NB: the tutorials are text notebooks (MyST Markdown with ``{code-cell}`` blocks)
that diff like any source file; MyST-NB executes them at every build and embeds what they print
and plot, so no number or figure in the docs can go stale; ``sphinx.ext.autodoc`` with
``napoleon`` reads the NumPy-style docstrings already in the code, and the API pages are generated
from each package's ``__all__`` (``_apigen.py``). Build with ``-W`` so every warning (a malformed
docstring, a broken reference, a failing cell) is an error. No network: no intersphinx, no remote
assets; figures are matplotlib PNGs.

    sphinx-build -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
if (ROOT / "src" / "fdikit").is_dir():
    # Document (and execute the tutorials against) this source tree, also in the notebook kernels.
    sys.path.insert(0, str(ROOT / "src"))
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT / "src")] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
# The notebook kernels inherit this environment: a non-interactive MPLBACKEND (Agg) there would
# keep the tutorials' figures out of the pages; the kernels' own inline backend embeds them.
os.environ.pop("MPLBACKEND", None)

import _apigen  # noqa: E402

import fdikit  # noqa: E402

project = "fdikit"
author = "fdikit developers"
copyright = "fdikit developers, MIT licence"
release = version = fdikit.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
]
exclude_patterns = ["_build", "README.md", "jupyter_execute", ".jupyter_cache", "**.ipynb_checkpoints"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb"}

# -- the API reference: one page per public package, written from its __all__ -------------------
_apigen.write(HERE / "api")
autosummary_generate = False
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"           # the NumPy docstrings state types and shapes themselves
autodoc_class_signature = "mixed"
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True
add_module_names = False

# -- MyST and the executed tutorials ----------------------------------------------------------
myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 3
nb_execution_mode = os.environ.get("FDIKIT_DOCS_EXECUTE", "force")   # "off" for a quick look
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_execution_in_temp = False          # cells run in the tutorial's folder; they cd to the repository
nb_merge_streams = True
nb_render_markdown_format = "myst"   # Markdown outputs (the paper map) may hold tables
nb_kernel_rgx_aliases = {".*": "python3"}

# -- HTML -----------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"fdikit {release}"
html_static_path: list[str] = []
