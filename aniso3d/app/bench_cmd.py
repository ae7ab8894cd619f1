"""``aniso3d bench``: the speed/size/accuracy sweep (see :mod:`aniso3d.bench`)."""

from __future__ import annotations

from aniso3d.bench.cli_tmp import register

__all__ = ["register"]
