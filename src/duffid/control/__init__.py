"""Control: the adaptive controller (design with python-control, runtime controller, its
FMU) and the closed loops of plant, identifier and controller."""
