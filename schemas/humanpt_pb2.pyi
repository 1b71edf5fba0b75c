from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class PerceptionMethod(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    PERCEPTION_METHOD_UNSPECIFIED: _ClassVar[PerceptionMethod]
    PERCEPTION_METHOD_PAPER: _ClassVar[PerceptionMethod]
    PERCEPTION_METHOD_WEIGHTED: _ClassVar[PerceptionMethod]

class TobStatus(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    TOB_STATUS_UNSPECIFIED: _ClassVar[TobStatus]
    TOB_STATUS_FULL: _ClassVar[TobStatus]
    TOB_STATUS_POSITION_ONLY: _ClassVar[TobStatus]
    TOB_STATUS_LOST: _ClassVar[TobStatus]

class ControlMode(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    CONTROL_MODE_UNSPECIFIED: _ClassVar[ControlMode]
    CONTROL_MODE_IDLE: _ClassVar[ControlMode]
    CONTROL_MODE_TRACK: _ClassVar[ControlMode]
    CONTROL_MODE_HOLD: _ClassVar[ControlMode]
    CONTROL_MODE_RETURN: _ClassVar[ControlMode]
    CONTROL_MODE_POSITION_ONLY: _ClassVar[ControlMode]
    CONTROL_MODE_LOST: _ClassVar[ControlMode]
    CONTROL_MODE_PLAYBACK: _ClassVar[ControlMode]
    CONTROL_MODE_CALIBRATE: _ClassVar[ControlMode]

class Severity(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    SEVERITY_UNSPECIFIED: _ClassVar[Severity]
    SEVERITY_DEBUG: _ClassVar[Severity]
    SEVERITY_INFO: _ClassVar[Severity]
    SEVERITY_WARNING: _ClassVar[Severity]
    SEVERITY_ERROR: _ClassVar[Severity]
    SEVERITY_FATAL: _ClassVar[Severity]
PERCEPTION_METHOD_UNSPECIFIED: PerceptionMethod
PERCEPTION_METHOD_PAPER: PerceptionMethod
PERCEPTION_METHOD_WEIGHTED: PerceptionMethod
TOB_STATUS_UNSPECIFIED: TobStatus
TOB_STATUS_FULL: TobStatus
TOB_STATUS_POSITION_ONLY: TobStatus
TOB_STATUS_LOST: TobStatus
CONTROL_MODE_UNSPECIFIED: ControlMode
CONTROL_MODE_IDLE: ControlMode
CONTROL_MODE_TRACK: ControlMode
CONTROL_MODE_HOLD: ControlMode
CONTROL_MODE_RETURN: ControlMode
CONTROL_MODE_POSITION_ONLY: ControlMode
CONTROL_MODE_LOST: ControlMode
CONTROL_MODE_PLAYBACK: ControlMode
CONTROL_MODE_CALIBRATE: ControlMode
SEVERITY_UNSPECIFIED: Severity
SEVERITY_DEBUG: Severity
SEVERITY_INFO: Severity
SEVERITY_WARNING: Severity
SEVERITY_ERROR: Severity
SEVERITY_FATAL: Severity

class Header(_message.Message):
    __slots__ = ("stamp_ns", "seq", "frame_id")
    STAMP_NS_FIELD_NUMBER: _ClassVar[int]
    SEQ_FIELD_NUMBER: _ClassVar[int]
    FRAME_ID_FIELD_NUMBER: _ClassVar[int]
    stamp_ns: int
    seq: int
    frame_id: str
    def __init__(self, stamp_ns: _Optional[int] = ..., seq: _Optional[int] = ..., frame_id: _Optional[str] = ...) -> None: ...

class Vector3(_message.Message):
    __slots__ = ("x", "y", "z")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ...) -> None: ...

class Quaternion(_message.Message):
    __slots__ = ("x", "y", "z", "w")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    Z_FIELD_NUMBER: _ClassVar[int]
    W_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    z: float
    w: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., z: _Optional[float] = ..., w: _Optional[float] = ...) -> None: ...

class Pose(_message.Message):
    __slots__ = ("translation", "rotation")
    TRANSLATION_FIELD_NUMBER: _ClassVar[int]
    ROTATION_FIELD_NUMBER: _ClassVar[int]
    translation: Vector3
    rotation: Quaternion
    def __init__(self, translation: _Optional[_Union[Vector3, _Mapping]] = ..., rotation: _Optional[_Union[Quaternion, _Mapping]] = ...) -> None: ...

class Point2(_message.Message):
    __slots__ = ("u", "v")
    U_FIELD_NUMBER: _ClassVar[int]
    V_FIELD_NUMBER: _ClassVar[int]
    u: float
    v: float
    def __init__(self, u: _Optional[float] = ..., v: _Optional[float] = ...) -> None: ...

class Pair(_message.Message):
    __slots__ = ("right", "left", "residual_px")
    RIGHT_FIELD_NUMBER: _ClassVar[int]
    LEFT_FIELD_NUMBER: _ClassVar[int]
    RESIDUAL_PX_FIELD_NUMBER: _ClassVar[int]
    right: int
    left: int
    residual_px: float
    def __init__(self, right: _Optional[int] = ..., left: _Optional[int] = ..., residual_px: _Optional[float] = ...) -> None: ...

class TobMeasurement(_message.Message):
    __slots__ = ("header", "centers_px", "pairs", "points_camera_m", "camera_T_tob", "visible", "quality", "method", "status", "processing_s", "degraded", "degraded_sources", "degraded_reason", "source_brightness")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    CENTERS_PX_FIELD_NUMBER: _ClassVar[int]
    PAIRS_FIELD_NUMBER: _ClassVar[int]
    POINTS_CAMERA_M_FIELD_NUMBER: _ClassVar[int]
    CAMERA_T_TOB_FIELD_NUMBER: _ClassVar[int]
    VISIBLE_FIELD_NUMBER: _ClassVar[int]
    QUALITY_FIELD_NUMBER: _ClassVar[int]
    METHOD_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    PROCESSING_S_FIELD_NUMBER: _ClassVar[int]
    DEGRADED_FIELD_NUMBER: _ClassVar[int]
    DEGRADED_SOURCES_FIELD_NUMBER: _ClassVar[int]
    DEGRADED_REASON_FIELD_NUMBER: _ClassVar[int]
    SOURCE_BRIGHTNESS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    centers_px: _containers.RepeatedCompositeFieldContainer[Point2]
    pairs: _containers.RepeatedCompositeFieldContainer[Pair]
    points_camera_m: _containers.RepeatedCompositeFieldContainer[Vector3]
    camera_T_tob: Pose
    visible: int
    quality: float
    method: PerceptionMethod
    status: TobStatus
    processing_s: float
    degraded: bool
    degraded_sources: _containers.RepeatedScalarFieldContainer[int]
    degraded_reason: str
    source_brightness: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., centers_px: _Optional[_Iterable[_Union[Point2, _Mapping]]] = ..., pairs: _Optional[_Iterable[_Union[Pair, _Mapping]]] = ..., points_camera_m: _Optional[_Iterable[_Union[Vector3, _Mapping]]] = ..., camera_T_tob: _Optional[_Union[Pose, _Mapping]] = ..., visible: _Optional[int] = ..., quality: _Optional[float] = ..., method: _Optional[_Union[PerceptionMethod, str]] = ..., status: _Optional[_Union[TobStatus, str]] = ..., processing_s: _Optional[float] = ..., degraded: _Optional[bool] = ..., degraded_sources: _Optional[_Iterable[int]] = ..., degraded_reason: _Optional[str] = ..., source_brightness: _Optional[_Iterable[float]] = ...) -> None: ...

class AlterStatus(_message.Message):
    __slots__ = ("alter_active", "tool_mode", "cumulative", "arm_power", "fault")
    ALTER_ACTIVE_FIELD_NUMBER: _ClassVar[int]
    TOOL_MODE_FIELD_NUMBER: _ClassVar[int]
    CUMULATIVE_FIELD_NUMBER: _ClassVar[int]
    ARM_POWER_FIELD_NUMBER: _ClassVar[int]
    FAULT_FIELD_NUMBER: _ClassVar[int]
    alter_active: bool
    tool_mode: bool
    cumulative: bool
    arm_power: bool
    fault: bool
    def __init__(self, alter_active: _Optional[bool] = ..., tool_mode: _Optional[bool] = ..., cumulative: _Optional[bool] = ..., arm_power: _Optional[bool] = ..., fault: _Optional[bool] = ...) -> None: ...

class RobotState(_message.Message):
    __slots__ = ("header", "world_T_flange", "joints_rad", "status", "cycle", "missed_cycles", "cycle_period_ns")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_FLANGE_FIELD_NUMBER: _ClassVar[int]
    JOINTS_RAD_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    MISSED_CYCLES_FIELD_NUMBER: _ClassVar[int]
    CYCLE_PERIOD_NS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    world_T_flange: Pose
    joints_rad: _containers.RepeatedScalarFieldContainer[float]
    status: AlterStatus
    cycle: int
    missed_cycles: int
    cycle_period_ns: int
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., world_T_flange: _Optional[_Union[Pose, _Mapping]] = ..., joints_rad: _Optional[_Iterable[float]] = ..., status: _Optional[_Union[AlterStatus, _Mapping]] = ..., cycle: _Optional[int] = ..., missed_cycles: _Optional[int] = ..., cycle_period_ns: _Optional[int] = ...) -> None: ...

class FlangeCommand(_message.Message):
    __slots__ = ("header", "cycle", "d_translation_m", "d_rotation_rad", "mode", "request_alter_off", "measurement_stamp_ns")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    D_TRANSLATION_M_FIELD_NUMBER: _ClassVar[int]
    D_ROTATION_RAD_FIELD_NUMBER: _ClassVar[int]
    MODE_FIELD_NUMBER: _ClassVar[int]
    REQUEST_ALTER_OFF_FIELD_NUMBER: _ClassVar[int]
    MEASUREMENT_STAMP_NS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    cycle: int
    d_translation_m: Vector3
    d_rotation_rad: Vector3
    mode: ControlMode
    request_alter_off: bool
    measurement_stamp_ns: int
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., cycle: _Optional[int] = ..., d_translation_m: _Optional[_Union[Vector3, _Mapping]] = ..., d_rotation_rad: _Optional[_Union[Vector3, _Mapping]] = ..., mode: _Optional[_Union[ControlMode, str]] = ..., request_alter_off: _Optional[bool] = ..., measurement_stamp_ns: _Optional[int] = ...) -> None: ...

class TobState(_message.Message):
    __slots__ = ("header", "world_T_tob", "linear_velocity_m_s", "angular_velocity_rad_s", "covariance", "covariance_dim", "status", "gated_outliers", "measurement_stamp_ns", "cycle", "measurements", "world_T_tob_at_measurement", "after_measurement", "world_T_tob_measured")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_FIELD_NUMBER: _ClassVar[int]
    LINEAR_VELOCITY_M_S_FIELD_NUMBER: _ClassVar[int]
    ANGULAR_VELOCITY_RAD_S_FIELD_NUMBER: _ClassVar[int]
    COVARIANCE_FIELD_NUMBER: _ClassVar[int]
    COVARIANCE_DIM_FIELD_NUMBER: _ClassVar[int]
    STATUS_FIELD_NUMBER: _ClassVar[int]
    GATED_OUTLIERS_FIELD_NUMBER: _ClassVar[int]
    MEASUREMENT_STAMP_NS_FIELD_NUMBER: _ClassVar[int]
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    MEASUREMENTS_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_AT_MEASUREMENT_FIELD_NUMBER: _ClassVar[int]
    AFTER_MEASUREMENT_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_MEASURED_FIELD_NUMBER: _ClassVar[int]
    header: Header
    world_T_tob: Pose
    linear_velocity_m_s: Vector3
    angular_velocity_rad_s: Vector3
    covariance: _containers.RepeatedScalarFieldContainer[float]
    covariance_dim: int
    status: TobStatus
    gated_outliers: int
    measurement_stamp_ns: int
    cycle: int
    measurements: int
    world_T_tob_at_measurement: Pose
    after_measurement: bool
    world_T_tob_measured: Pose
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., world_T_tob: _Optional[_Union[Pose, _Mapping]] = ..., linear_velocity_m_s: _Optional[_Union[Vector3, _Mapping]] = ..., angular_velocity_rad_s: _Optional[_Union[Vector3, _Mapping]] = ..., covariance: _Optional[_Iterable[float]] = ..., covariance_dim: _Optional[int] = ..., status: _Optional[_Union[TobStatus, str]] = ..., gated_outliers: _Optional[int] = ..., measurement_stamp_ns: _Optional[int] = ..., cycle: _Optional[int] = ..., measurements: _Optional[int] = ..., world_T_tob_at_measurement: _Optional[_Union[Pose, _Mapping]] = ..., after_measurement: _Optional[bool] = ..., world_T_tob_measured: _Optional[_Union[Pose, _Mapping]] = ...) -> None: ...

class ControllerStatus(_message.Message):
    __slots__ = ("header", "mode", "visible", "error_translation_m", "error_rotation_rad", "cycle_misses", "recording", "path_points", "calibration_samples", "cycle", "saturated", "world_T_desired", "fov_margin_px", "image_error_px", "rotation_scale")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    MODE_FIELD_NUMBER: _ClassVar[int]
    VISIBLE_FIELD_NUMBER: _ClassVar[int]
    ERROR_TRANSLATION_M_FIELD_NUMBER: _ClassVar[int]
    ERROR_ROTATION_RAD_FIELD_NUMBER: _ClassVar[int]
    CYCLE_MISSES_FIELD_NUMBER: _ClassVar[int]
    RECORDING_FIELD_NUMBER: _ClassVar[int]
    PATH_POINTS_FIELD_NUMBER: _ClassVar[int]
    CALIBRATION_SAMPLES_FIELD_NUMBER: _ClassVar[int]
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    SATURATED_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_DESIRED_FIELD_NUMBER: _ClassVar[int]
    FOV_MARGIN_PX_FIELD_NUMBER: _ClassVar[int]
    IMAGE_ERROR_PX_FIELD_NUMBER: _ClassVar[int]
    ROTATION_SCALE_FIELD_NUMBER: _ClassVar[int]
    header: Header
    mode: ControlMode
    visible: int
    error_translation_m: float
    error_rotation_rad: float
    cycle_misses: int
    recording: bool
    path_points: int
    calibration_samples: int
    cycle: int
    saturated: bool
    world_T_desired: Pose
    fov_margin_px: float
    image_error_px: float
    rotation_scale: float
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., mode: _Optional[_Union[ControlMode, str]] = ..., visible: _Optional[int] = ..., error_translation_m: _Optional[float] = ..., error_rotation_rad: _Optional[float] = ..., cycle_misses: _Optional[int] = ..., recording: _Optional[bool] = ..., path_points: _Optional[int] = ..., calibration_samples: _Optional[int] = ..., cycle: _Optional[int] = ..., saturated: _Optional[bool] = ..., world_T_desired: _Optional[_Union[Pose, _Mapping]] = ..., fov_margin_px: _Optional[float] = ..., image_error_px: _Optional[float] = ..., rotation_scale: _Optional[float] = ...) -> None: ...

class PathPoint(_message.Message):
    __slots__ = ("header", "index", "world_T_tob", "has_tip", "world_T_tip", "orientation_held", "position_covariance_m2", "rotation_covariance_rad2", "tip_position_covariance_m2", "world_T_tob_raw", "world_T_tip_raw")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    INDEX_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_FIELD_NUMBER: _ClassVar[int]
    HAS_TIP_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TIP_FIELD_NUMBER: _ClassVar[int]
    ORIENTATION_HELD_FIELD_NUMBER: _ClassVar[int]
    POSITION_COVARIANCE_M2_FIELD_NUMBER: _ClassVar[int]
    ROTATION_COVARIANCE_RAD2_FIELD_NUMBER: _ClassVar[int]
    TIP_POSITION_COVARIANCE_M2_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_RAW_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TIP_RAW_FIELD_NUMBER: _ClassVar[int]
    header: Header
    index: int
    world_T_tob: Pose
    has_tip: bool
    world_T_tip: Pose
    orientation_held: bool
    position_covariance_m2: _containers.RepeatedScalarFieldContainer[float]
    rotation_covariance_rad2: _containers.RepeatedScalarFieldContainer[float]
    tip_position_covariance_m2: _containers.RepeatedScalarFieldContainer[float]
    world_T_tob_raw: Pose
    world_T_tip_raw: Pose
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., index: _Optional[int] = ..., world_T_tob: _Optional[_Union[Pose, _Mapping]] = ..., has_tip: _Optional[bool] = ..., world_T_tip: _Optional[_Union[Pose, _Mapping]] = ..., orientation_held: _Optional[bool] = ..., position_covariance_m2: _Optional[_Iterable[float]] = ..., rotation_covariance_rad2: _Optional[_Iterable[float]] = ..., tip_position_covariance_m2: _Optional[_Iterable[float]] = ..., world_T_tob_raw: _Optional[_Union[Pose, _Mapping]] = ..., world_T_tip_raw: _Optional[_Union[Pose, _Mapping]] = ...) -> None: ...

class Truth(_message.Message):
    __slots__ = ("header", "world_T_tob", "has_tip", "world_T_tip", "world_T_flange", "cover_fraction", "cover_angle_rad")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TOB_FIELD_NUMBER: _ClassVar[int]
    HAS_TIP_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_TIP_FIELD_NUMBER: _ClassVar[int]
    WORLD_T_FLANGE_FIELD_NUMBER: _ClassVar[int]
    COVER_FRACTION_FIELD_NUMBER: _ClassVar[int]
    COVER_ANGLE_RAD_FIELD_NUMBER: _ClassVar[int]
    header: Header
    world_T_tob: Pose
    has_tip: bool
    world_T_tip: Pose
    world_T_flange: Pose
    cover_fraction: _containers.RepeatedScalarFieldContainer[float]
    cover_angle_rad: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., world_T_tob: _Optional[_Union[Pose, _Mapping]] = ..., has_tip: _Optional[bool] = ..., world_T_tip: _Optional[_Union[Pose, _Mapping]] = ..., world_T_flange: _Optional[_Union[Pose, _Mapping]] = ..., cover_fraction: _Optional[_Iterable[float]] = ..., cover_angle_rad: _Optional[_Iterable[float]] = ...) -> None: ...

class Event(_message.Message):
    __slots__ = ("header", "severity", "source", "code", "text")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    SEVERITY_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    CODE_FIELD_NUMBER: _ClassVar[int]
    TEXT_FIELD_NUMBER: _ClassVar[int]
    header: Header
    severity: Severity
    source: str
    code: str
    text: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., severity: _Optional[_Union[Severity, str]] = ..., source: _Optional[str] = ..., code: _Optional[str] = ..., text: _Optional[str] = ...) -> None: ...

class Tick(_message.Message):
    __slots__ = ("header", "period_ns")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    PERIOD_NS_FIELD_NUMBER: _ClassVar[int]
    header: Header
    period_ns: int
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., period_ns: _Optional[int] = ...) -> None: ...

class ParamSet(_message.Message):
    __slots__ = ("header", "component", "key", "value_json")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    COMPONENT_FIELD_NUMBER: _ClassVar[int]
    KEY_FIELD_NUMBER: _ClassVar[int]
    VALUE_JSON_FIELD_NUMBER: _ClassVar[int]
    header: Header
    component: str
    key: str
    value_json: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., component: _Optional[str] = ..., key: _Optional[str] = ..., value_json: _Optional[str] = ...) -> None: ...

class SerialChunk(_message.Message):
    __slots__ = ("header", "data", "outgoing")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    OUTGOING_FIELD_NUMBER: _ClassVar[int]
    header: Header
    data: bytes
    outgoing: bool
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., data: _Optional[bytes] = ..., outgoing: _Optional[bool] = ...) -> None: ...

class Command(_message.Message):
    __slots__ = ("header", "component", "verb", "args_json")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    COMPONENT_FIELD_NUMBER: _ClassVar[int]
    VERB_FIELD_NUMBER: _ClassVar[int]
    ARGS_JSON_FIELD_NUMBER: _ClassVar[int]
    header: Header
    component: str
    verb: str
    args_json: str
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., component: _Optional[str] = ..., verb: _Optional[str] = ..., args_json: _Optional[str] = ...) -> None: ...

class Liveliness(_message.Message):
    __slots__ = ("header", "component", "alive")
    HEADER_FIELD_NUMBER: _ClassVar[int]
    COMPONENT_FIELD_NUMBER: _ClassVar[int]
    ALIVE_FIELD_NUMBER: _ClassVar[int]
    header: Header
    component: str
    alive: bool
    def __init__(self, header: _Optional[_Union[Header, _Mapping]] = ..., component: _Optional[str] = ..., alive: _Optional[bool] = ...) -> None: ...
