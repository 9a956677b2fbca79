"""``hcard view``: a local page to see and try cards.

- :mod:`hcard.view.model`: what the page shows, as numbers (the cards' maps, a texture's
  spatial profile and spectrum, a stroke rendered by the core renderer, the difference of two
  cards, the error of a card against its source image).
- :mod:`hcard.view.server`: the HTTP server on 127.0.0.1 that serves the page
  (``hcard/view/static/``) and those numbers as JSON.

The page computes nothing of its own: every number it plots comes from the server, and every
rendering from :class:`hcard.render.Renderer`, the renderer of ``hcard render``.
"""
