"""FMU building blocks: the variable table, modelDescription.xml for FMI 2.0 and 3.0, the C
build and the deterministic archive, and the estimator FMUs (C core and pythonfmu)."""
