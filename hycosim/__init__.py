"""The ``hycosim`` command line: validate, server, node, run, report, plot, status."""
