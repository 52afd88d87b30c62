"""Analyses on top of identification: the Hilbert-transform nonlinearity index and the
Silverbox study of real measurements."""
