"""A picture of a card a person can read (``hcard preview``, ``hcard encode --preview``).

- :mod:`hcard.preview.picture`: the whole picture (the taxtel map, the error map, the texture
  profiles and their legend, title) as a figure or PNG bytes or file: :func:`~hcard.preview.picture.
  render_preview`, :func:`~hcard.preview.picture.preview_png`,
  :func:`~hcard.preview.picture.preview_figure`;
- :mod:`hcard.preview.periods`: each texture's relative friction and UV/EV drives over one
  length (and time) shared by all textures, as small multiples;
- :mod:`hcard.preview.error_map`: each taxtel's error in JND over the surface, coloured over the
  map's own range;
- :mod:`hcard.preview.glyph_labels`: many short labels drawn as one collection of glyph outlines
  (also the calibration report's tick labels, :mod:`hcard.calibration.report.figures`).

matplotlib is imported by these modules only, so a command that draws nothing never loads it.
"""
