"""Rendering on the GPU: context, shaders, camera, lighting, the three renderers and the Renderer front."""
