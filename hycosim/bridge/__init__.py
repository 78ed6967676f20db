"""FMU export: native bridge FMUs and Python model FMUs, the gateway protocol they speak and
the gateway beside the relay server that they talk to."""
