"""Probe box, cameras and rig (``RIGS``), and the camera rays that cross the box."""
from nerif.geometry.box import FACES, ProbeBox, box_faces, face_names, sample_volume
from nerif.geometry.camera import RIGS, Camera, arc_rig, camera_from_nerf_pose, look_at_origin, rig_axis
from nerif.geometry.rays import (outside_the_box, pixels_per_voxel, ray_binning, ray_spacing_mm, rays_in_box,
                                  view_index)

__all__ = ["FACES", "ProbeBox", "box_faces", "face_names", "sample_volume", "RIGS", "Camera", "arc_rig",
           "camera_from_nerf_pose", "look_at_origin", "outside_the_box", "rig_axis", "pixels_per_voxel", "ray_binning", "ray_spacing_mm", "rays_in_box", "view_index"]
