"""duffid: online algebraic identification of nonlinear oscillators."""
