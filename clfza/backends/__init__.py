"""Array backends for the solvers: numpy float64 reference and OpenCL."""
