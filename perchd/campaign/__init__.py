"""Campaigns: many simulated flights as one study. What a flight is drawn from (flights.py),
how flights are batched into work units (batches.py) and run on an engine (engine.py: the
local pool or Dask, dask_engine.py), the table they make (results.py, tableformats.py), its
plots (plot.py), and one member of the vehicle family flown as a row (familyrun.py)."""
