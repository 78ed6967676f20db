"""FMUs for hycosim: loading (co-simulation and Model Exchange), model and bridge FMU building,
the bridge FMUs' gateway protocol, SSP packages. The shared core is in ``hycosim.core``."""
