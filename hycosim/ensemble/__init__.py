"""Many runs at once: parameter sweeps and Monte Carlo ensembles of whole co-simulations, each
run in process on a Dask worker (variants.py: the runs asked for; runs.py: one run, on a
worker; sweep.py: the runs handed to Dask and their table). ``hycosim.sweep`` and ``hycosim
sweep`` are the ways in. Needs the ``[ensemble]`` extra (dask[distributed], pyarrow)."""
