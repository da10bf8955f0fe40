"""Geometry stages: skeletons, frusta, meshes, reference ray casting. No GL, no click."""

from .skeletons.skeleton import Skeleton, SkeletonError

__all__ = ["Skeleton", "SkeletonError"]
