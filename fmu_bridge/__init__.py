"""The shared wire of hycosim: project config, frames, Zenoh keys and sessions, FMUs."""

__version__ = "0.1.0"
