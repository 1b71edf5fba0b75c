"""PSVS geometry and the target model: eq. (1)-(13) of Pachidis et al. as a pure
numpy/scipy library (no I/O). Lengths in mm, image coordinates in px, angles in degrees
where a person reads them; transforms are 4x4 arrays named ``a_T_b``.

See ``README.md`` in this folder for the function -> equation table.
"""

from .calibration import (
    TipCalibration,
    calibrate_tip_paper,
    calibrate_tip_pivot,
    world_point_from_samples,
)
from .distortion import (
    distort_normalised,
    distort_pixels,
    normalise_pixels,
    pixels_from_normalised,
    undistort_normalised,
    undistort_pixels,
)
from .error_model import (
    monte_carlo_pose_x,
    point_covariance_mm2,
    point_sigma_mm,
    pose_covariance,
    pose_sigma,
    wrap_angle_deg,
)
from .errors import GeometryError
from .psvs import (
    TRIANGULATION_METHODS,
    PinholeCamera,
    PsvsParams,
    eq4_points_mm,
    in_image,
    intrinsic_matrix,
    parallel_pixels,
    project,
    project_pinhole,
    projection_jacobian,
    psvs_m_l_mm,
    refraction_angle_deg,
    triangulate,
    triangulate_eq2,
    triangulate_eq4,
    triangulate_lsq,
    virtual_camera_centres_mm,
    virtual_rotation_from_mirror_tilt_deg,
)
from .rig import (
    DEFAULT_DZ_MM,
    DEFAULT_FLANGE_T_CAMERA_MM,
    camera_T_desired,
    flange_T_desired,
    viewing_world_T_flange,
)
from .target import (
    Labelling,
    TargetModel,
    estimate_camera_T_tob,
    isosceles_source_positions_mm,
    label_sources,
    tip_pose,
    tob_frame_from_points,
    tob_T_tip_on_w_axis,
    triangle_sides_mm,
)
from .transforms import (
    apply_step,
    chain_world_T_tob,
    check_rigid,
    compose,
    interpolate_transform,
    invert_transform,
    make_transform,
    matrix_from_rotvec,
    rotation_angle_rad,
    rotation_from_ypr_deg,
    rotvec_from_matrix,
    slerp,
    transform_from_x,
    transform_points,
    x_from_transform,
    ypr_deg_from_rotation,
)

__all__ = [
    "GeometryError",
    # psvs (eq. 1-6)
    "PinholeCamera",
    "PsvsParams",
    "TRIANGULATION_METHODS",
    "eq4_points_mm",
    "in_image",
    "intrinsic_matrix",
    "parallel_pixels",
    "project",
    "project_pinhole",
    "projection_jacobian",
    "psvs_m_l_mm",
    "refraction_angle_deg",
    "triangulate",
    "triangulate_eq2",
    "triangulate_eq4",
    "triangulate_lsq",
    "virtual_camera_centres_mm",
    "virtual_rotation_from_mirror_tilt_deg",
    # distortion
    "distort_normalised",
    "distort_pixels",
    "normalise_pixels",
    "pixels_from_normalised",
    "undistort_normalised",
    "undistort_pixels",
    # target (eq. 7-9)
    "Labelling",
    "TargetModel",
    "estimate_camera_T_tob",
    "isosceles_source_positions_mm",
    "label_sources",
    "tip_pose",
    "tob_frame_from_points",
    "tob_T_tip_on_w_axis",
    "triangle_sides_mm",
    # transforms, chains, X
    "apply_step",
    "chain_world_T_tob",
    "check_rigid",
    "compose",
    "interpolate_transform",
    "invert_transform",
    "make_transform",
    "matrix_from_rotvec",
    "rotation_angle_rad",
    "rotation_from_ypr_deg",
    "rotvec_from_matrix",
    "slerp",
    "transform_from_x",
    "transform_points",
    "x_from_transform",
    "ypr_deg_from_rotation",
    # rig: default hand-eye, desired point D (Section 5)
    "DEFAULT_DZ_MM",
    "DEFAULT_FLANGE_T_CAMERA_MM",
    "camera_T_desired",
    "flange_T_desired",
    "viewing_world_T_flange",
    # calibration (eq. 10-13)
    "TipCalibration",
    "calibrate_tip_paper",
    "calibrate_tip_pivot",
    "world_point_from_samples",
    # error model
    "monte_carlo_pose_x",
    "point_covariance_mm2",
    "point_sigma_mm",
    "pose_covariance",
    "pose_sigma",
    "wrap_angle_deg",
]
