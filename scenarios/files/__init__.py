"""What a command writes and reads, and nothing it computes: the columns of
truth.csv, telemetry.csv and estimate.csv (``columns``), fast exact CSV
(``csvio``), comparison.npz whole (``comparison``) or window by window
(``decimate``), summary.json (``summary``), `simulate`'s files (``simulation``),
real telemetry and truth files read back (``telemetry_file``, ``truth_file``; an
attitude history as the truth, ``truth_aem``), CCSDS attitude messages written and
read (``aem``) and run directories written whole or not at all (``rundir``).

May import: ``estimator`` and ``sim`` (types and constants only), ``config`` and the
base modules.  Not ``bridge``, its sibling: files hold numbers, the bridge turns
them into the filters' coordinates.
"""
