"""Records and where they come from: the Record and its readers (CSV, .mat, column maps,
units), excitation signals, and the simulation of models."""
