"""The calibration report: what the loop found, for people (Markdown, PNG) and programs (JSON).

:func:`hcard.calibration.report.writer.write_report` writes into a directory (file names in
:mod:`hcard.calibration.report.files`):

- ``report.md`` (:mod:`hcard.calibration.report.markdown_text`): leads with the held-out error
  before and after and the verdict, then the effects added with their fitted parameters, the
  selection criterion, the data, every candidate of every round, the effects skipped, the
  structure left, the residual analysis before and after, the base and final parameters, the
  figures and the wall time;
- ``report.json`` (:mod:`hcard.calibration.report.json_document`): the same content, format
  ``hcard-calibration-report/1``, finite numbers only (NaN and infinities become ``null``),
  with the fitted profile;
- ``profile.json``: the fitted device profile (:mod:`hcard.calibration.profile`);
- ``residuals.png`` and ``fit.png`` (:mod:`hcard.calibration.report.figures`): the binned
  residual against each regressor before and after, and the observed and predicted lateral
  force on held-out samples.

Numbers in the text and the figures are written by :mod:`hcard.calibration.report.number_text`.
Every file is written atomically (:func:`hcard.atomic.write_atomically`).
"""
