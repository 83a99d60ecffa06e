"""`dynprop export`: a run directory's attitude (the estimate, or the truth) as a CCSDS
attitude message another tool reads (docs/outputs.md, "estimate.aem, truth.aem").
``source``: the directory's scenario and its estimate.csv or truth.csv, streamed in
blocks of rows; ``write``: the AEM (every row) or the APM (one time, ``--at``),
written to a temporary file renamed at the end; ``compare``: the exported attitude
against another tool's AEM (``--truth``).

May import: ``files``, ``config`` and the base modules.  Not ``run`` or any analysis:
an export reads files only.
"""
