"""Many runs at once: parameter sweeps and Monte Carlo ensembles of whole co-simulations, each
run on a Dask worker (variants.py: the runs asked for; runs.py: one run, on a worker; sweep.py:
a sweep's runs and their table; cluster.py: the client and the jobs handed to it, which the
paper's trials use too). ``hycosim.sweep`` and ``hycosim sweep`` are the ways in. Needs the
``[ensemble]`` extra (dask[distributed], pyarrow)."""
