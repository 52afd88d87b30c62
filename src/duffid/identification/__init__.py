"""Identification: the O(1) regressors and moments, the online engine (robust and paper
methods), the buffered methods over orthogonal bases, the C core binding, the checks and
publication of a record's estimate (trust), and the output-error refinement."""
