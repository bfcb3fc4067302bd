"""rally3d training: Lightning modules and data modules, losses, metrics, dataset converters and the
synthetic rally generator. Builds on :mod:`inference`; nothing at run time depends on it."""
