"""Deprecated since 0.3.0: :mod:`hycosim.master.report`, re-exported for one release."""

import warnings

from hycosim.master.report import (EndedBy, ModeSwitchRecord, RunDirError, RunMeta, RunSummary, ScenarioRecord,
                                   envelope, plot_run, read_columns, read_events, read_meta, read_scenario,
                                   read_steps, summarise)

__all__ = ["EndedBy", "ModeSwitchRecord", "RunDirError", "RunMeta", "RunSummary", "ScenarioRecord", "envelope",
           "plot_run", "read_columns", "read_events", "read_meta", "read_scenario", "read_steps", "summarise"]

warnings.warn("hycosim.server.report is deprecated since 0.3.0 and goes in 0.4.0: import hycosim.master.report",
              DeprecationWarning, stacklevel=2)
