"""Geometry stages: skeletons, frusta, meshes, reference ray casting. No GL, no click."""

from .skeleton import Skeleton, SkeletonError

__all__ = ["Skeleton", "SkeletonError"]
