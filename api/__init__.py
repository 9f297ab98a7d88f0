import analysis  # noqa: F401  (first: it pins the BLAS kernel before numpy loads, analysis/blas.py)
