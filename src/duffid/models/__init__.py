"""Model structures: the oscillator chains (Duffing1, Duffing2, the circuit, n-DOF chains),
the regression structure every method works on, and equations typed by the user with
their integrated-by-parts regressors derived by CasADi."""
