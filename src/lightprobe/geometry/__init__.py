"""Geometry: meshes, analytic shapes, the camera, scenes and ray queries (Y up, right-handed)."""

from .camera import Camera
from .mesh import TriangleMesh
from .raytracer import RayTracer
from .scene import Scene
from .shapes import Rectangle, Sphere

__all__ = ["Camera", "RayTracer", "Rectangle", "Scene", "Sphere", "TriangleMesh"]
