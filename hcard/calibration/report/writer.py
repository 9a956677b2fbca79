"""Write a calibration report into a directory (:mod:`hcard.calibration.report`): the
Markdown, the JSON, the fitted profile and the figures, each file atomically."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hcard.atomic import write_atomically
from hcard.calibration.profile import profile_of
from hcard.calibration.report.figures import figure_png, fit_figure, residuals_figure
from hcard.calibration.report.files import FIT_PNG, JSON, MARKDOWN, PROFILE, RESIDUALS_PNG
from hcard.calibration.report.json_document import report_dict
from hcard.calibration.report.markdown_text import report_markdown
from hcard.calibration.results import CalibrationResult
from hcard.file_errors import writing
from hcard.physics import PredictorError
from hcard.physics.profile import DeviceProfile


@dataclass(frozen=True)
class ReportFiles:
    """The files :func:`write_report` wrote.

    Attributes:
        markdown: ``report.md``.
        json: ``report.json``.
        profile: ``profile.json``.
        figures: the PNG figures (empty with ``figures=False``).
    """

    markdown: Path
    json: Path
    profile: Path
    figures: list[Path] = field(default_factory=list)


def write_report(
    result: CalibrationResult,
    directory: str | os.PathLike[str],
    *,
    figures: bool = True,
    profile: DeviceProfile | None = None,
    rendering: Mapping[str, Any] | None = None,
) -> ReportFiles:
    """Write the report of ``result`` into ``directory`` (created if needed): the files
    :mod:`hcard.calibration.report` lists.

    ``profile``: the fitted device profile (default: :func:`~hcard.calibration.profile.
    profile_of` the result, for a bare predictor); ``rendering``: the rendering errors measured
    on a device without and with it, when they were.

    Raises:
        PredictorError: ``directory`` exists but is not a directory, or cannot be created.
    """
    folder = Path(directory)
    if folder.exists() and not folder.is_dir():
        raise PredictorError(f"{folder}: exists and is not a directory; cannot write a report")
    with writing(folder, PredictorError, "create the report directory"):
        folder.mkdir(parents=True, exist_ok=True)
    profile = profile if profile is not None else profile_of(result)

    written: list[Path] = []
    if figures:
        for name, draw in ((RESIDUALS_PNG, residuals_figure), (FIT_PNG, fit_figure)):
            path = folder / name
            write_atomically(path, figure_png(draw(result)))
            written.append(path)
    names = [p.name for p in written]
    profile_path = folder / PROFILE
    write_atomically(profile_path, profile.to_json())
    content = report_dict(result, names, profile=profile, rendering=rendering)
    text = json.dumps(content, indent=2, allow_nan=False, ensure_ascii=False)
    report_json = folder / JSON
    write_atomically(report_json, (text + "\n").encode("utf-8"))
    markdown = folder / MARKDOWN
    write_atomically(markdown, report_markdown(result, names, rendering=rendering).encode("utf-8"))
    return ReportFiles(markdown=markdown, json=report_json, profile=profile_path,
                       figures=written)
