"""Geometry: meshes, analytic shapes, the camera and ray queries (Y up, right-handed); the scene that holds them
with its materials and lights is :mod:`lightprobe.scene`."""

from .camera import Camera
from .mesh import TriangleMesh
from .raytracer import RayTracer
from .shapes import Rectangle, Sphere

__all__ = ["Camera", "RayTracer", "Rectangle", "Sphere", "TriangleMesh"]
