//! Geometries (boxes, spheres, rotated and united shapes) and obstacles, generic over the backend.
