"""The commands of ``hycosim``, one module per domain; ``hycosim.cli.main`` registers them."""
