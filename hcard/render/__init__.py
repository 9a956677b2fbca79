"""The hybrid renderer (spec/README.md section 6; thesis chapter 5).

A card plus a finger track becomes target relative friction per channel (UV, EV) at the frame
rate: Position control picks the taxtel under the dead-reckoned finger, Texture control plays
the taxtel's texture with phase integrated from the finger velocity.
"""

from hcard.render.options import RenderMode, RenderOptions
from hcard.render.renderer import (
    MAX_RENDER_FRAMES,
    Frames,
    Renderer,
    RenderStream,
    RenderTooLong,
    render,
)

__all__ = ["MAX_RENDER_FRAMES", "Frames", "RenderMode", "RenderOptions", "RenderStream",
           "RenderTooLong", "Renderer", "render"]
