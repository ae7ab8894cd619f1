"""Front ends: the aniso3d command (build, render, frames, bench, view) and the interactive viewer."""
