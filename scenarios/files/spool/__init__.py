"""A telemetry file read in blocks into raw scratch columns (issue 44: telemetry of any
length): ``blocks`` reads a CSV or Parquet file a block at a time with the whole
reader's values and messages, ``times`` dates its rows, ``screening`` screens them
across block boundaries, ``select`` finds an exact median on disk, and ``source``
keeps the columns on disk and answers by range (``telemetry_source.TelemetrySource``).
"""
