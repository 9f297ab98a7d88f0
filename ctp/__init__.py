"""The command line on top of everything: ``ctp analyze | modes | simulate | plan | batch | schema``."""

import analysis  # noqa: F401  (first: it pins the BLAS kernel before numpy loads, analysis/blas.py)
