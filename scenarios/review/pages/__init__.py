"""The pages of the directories the other commands write (docs/outputs.md): a Monte
Carlo set (``ensemble``, its figures ``ensemble_figures``), the linearization report
(``linearization``), `trim`, `tune`, `batch` and `simulate`, each
``build(src, command, requirement_deg) -> render.Page`` as ``run_page``'s: its verdicts
where the record has them, its figures, the record's every number (each a
``cells.cell`` tied to its file and key) and the closing provenance sections.

Part of the ``review`` room: may import what ``review`` may.
"""
