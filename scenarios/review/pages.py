"""The pages of the directories the other commands write (docs/outputs.md): a Monte
Carlo set, the linearization report, `trim`, `tune`, `batch` and `simulate`, each
``build(src, command, requirement_deg) -> render.Page`` as run_page's: its verdicts
where the record has them, its figures, the record's every number (each a
``cells.cell`` tied to its file and key) and the closing provenance sections.
"""

from __future__ import annotations

from . import batch_page, ensemble_page, linearization_page, simulate_page, trim_page, tune_page

BUILDERS = {
    "montecarlo": ensemble_page.build,
    "linearization": linearization_page.build,
    "trim": trim_page.build,
    "tune": tune_page.build,
    "batch": batch_page.build,
    "simulate": simulate_page.build,
}
