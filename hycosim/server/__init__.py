"""Deprecated since 0.3.0: the master (the relay, its algorithms, recorders and observers) is
:mod:`hycosim.master`. Kept for one release so that code reading run directories through
``hycosim.server.report`` still runs."""

import warnings

warnings.warn("hycosim.server is deprecated since 0.3.0 and goes in 0.4.0: import hycosim.master "
              "(hycosim.master.report reads run directories)", DeprecationWarning, stacklevel=2)
