"""Probe box, cameras and rays."""
from nerif.geometry.box import ProbeBox, face_axes, sample_volume
from nerif.geometry.camera import Camera, arc_rig, camera_from_nerf_pose, look_at_origin

__all__ = ["ProbeBox", "face_axes", "sample_volume", "Camera", "arc_rig", "camera_from_nerf_pose", "look_at_origin"]
