"""Building: mesh -> clipped facets -> anisotropic texture -> oriented points and the LOD pyramid (CPU, NumPy)."""
