"""Textures: material parameters that vary over a surface (image textures through UVs, vertex
colours), evaluated per hit in batches.  Layer: above spectral, below materials."""

from .inputs import (TexturedNumber, TexturedSpectrum, TextureInput, parse_texture_input, textured,
                     textured_emission)
from .surface import SurfacePoints, VertexAttributes
from .texture import ImageTexture, Texture, VertexColour

__all__ = ["ImageTexture", "SurfacePoints", "Texture", "TextureInput", "TexturedNumber", "TexturedSpectrum",
           "VertexAttributes", "VertexColour", "parse_texture_input", "textured", "textured_emission"]
