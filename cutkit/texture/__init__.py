"""3D-texture registration (paper section 7.2)."""

from cutkit.texture.register import TextureReport, downsample_texture, fit_transform, register_texture

__all__ = ["TextureReport", "downsample_texture", "fit_transform", "register_texture"]
