"""Skeleton and skin: the skeleton, its topology, SWC files, frames, the frusta and the
skin built on them, relief maps, materials, the sway rig and its skin."""
