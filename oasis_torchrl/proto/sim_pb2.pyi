from google.protobuf.internal import containers as _containers
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class FrameTruth(_message.Message):
    __slots__ = ("x", "y", "heading", "speed", "distance", "progress", "lateral_offset", "heading_error", "collided", "obstacle_distance", "off_road", "obstacle_distance_left", "obstacle_distance_right", "lane_offset", "lanes_left", "lanes_right", "lane_obstacle_distance", "lane_obstacle_distance_left", "lane_obstacle_distance_right")
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    HEADING_FIELD_NUMBER: _ClassVar[int]
    SPEED_FIELD_NUMBER: _ClassVar[int]
    DISTANCE_FIELD_NUMBER: _ClassVar[int]
    PROGRESS_FIELD_NUMBER: _ClassVar[int]
    LATERAL_OFFSET_FIELD_NUMBER: _ClassVar[int]
    HEADING_ERROR_FIELD_NUMBER: _ClassVar[int]
    COLLIDED_FIELD_NUMBER: _ClassVar[int]
    OBSTACLE_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    OFF_ROAD_FIELD_NUMBER: _ClassVar[int]
    OBSTACLE_DISTANCE_LEFT_FIELD_NUMBER: _ClassVar[int]
    OBSTACLE_DISTANCE_RIGHT_FIELD_NUMBER: _ClassVar[int]
    LANE_OFFSET_FIELD_NUMBER: _ClassVar[int]
    LANES_LEFT_FIELD_NUMBER: _ClassVar[int]
    LANES_RIGHT_FIELD_NUMBER: _ClassVar[int]
    LANE_OBSTACLE_DISTANCE_FIELD_NUMBER: _ClassVar[int]
    LANE_OBSTACLE_DISTANCE_LEFT_FIELD_NUMBER: _ClassVar[int]
    LANE_OBSTACLE_DISTANCE_RIGHT_FIELD_NUMBER: _ClassVar[int]
    x: float
    y: float
    heading: float
    speed: float
    distance: float
    progress: float
    lateral_offset: float
    heading_error: float
    collided: bool
    obstacle_distance: float
    off_road: bool
    obstacle_distance_left: float
    obstacle_distance_right: float
    lane_offset: float
    lanes_left: int
    lanes_right: int
    lane_obstacle_distance: float
    lane_obstacle_distance_left: float
    lane_obstacle_distance_right: float
    def __init__(self, x: _Optional[float] = ..., y: _Optional[float] = ..., heading: _Optional[float] = ..., speed: _Optional[float] = ..., distance: _Optional[float] = ..., progress: _Optional[float] = ..., lateral_offset: _Optional[float] = ..., heading_error: _Optional[float] = ..., collided: _Optional[bool] = ..., obstacle_distance: _Optional[float] = ..., off_road: _Optional[bool] = ..., obstacle_distance_left: _Optional[float] = ..., obstacle_distance_right: _Optional[float] = ..., lane_offset: _Optional[float] = ..., lanes_left: _Optional[int] = ..., lanes_right: _Optional[int] = ..., lane_obstacle_distance: _Optional[float] = ..., lane_obstacle_distance_left: _Optional[float] = ..., lane_obstacle_distance_right: _Optional[float] = ...) -> None: ...

class InferTruth(_message.Message):
    __slots__ = ("sequence_num", "seed", "frames", "expert_actions")
    SEQUENCE_NUM_FIELD_NUMBER: _ClassVar[int]
    SEED_FIELD_NUMBER: _ClassVar[int]
    FRAMES_FIELD_NUMBER: _ClassVar[int]
    EXPERT_ACTIONS_FIELD_NUMBER: _ClassVar[int]
    sequence_num: int
    seed: int
    frames: _containers.RepeatedCompositeFieldContainer[FrameTruth]
    expert_actions: _containers.RepeatedScalarFieldContainer[float]
    def __init__(self, sequence_num: _Optional[int] = ..., seed: _Optional[int] = ..., frames: _Optional[_Iterable[_Union[FrameTruth, _Mapping]]] = ..., expert_actions: _Optional[_Iterable[float]] = ...) -> None: ...

class DepthRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class DepthMap(_message.Message):
    __slots__ = ("name", "height", "width", "depth_f16")
    NAME_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_FIELD_NUMBER: _ClassVar[int]
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    DEPTH_F16_FIELD_NUMBER: _ClassVar[int]
    name: str
    height: int
    width: int
    depth_f16: bytes
    def __init__(self, name: _Optional[str] = ..., height: _Optional[int] = ..., width: _Optional[int] = ..., depth_f16: _Optional[bytes] = ...) -> None: ...

class DepthResponse(_message.Message):
    __slots__ = ("sequence_num", "maps")
    SEQUENCE_NUM_FIELD_NUMBER: _ClassVar[int]
    MAPS_FIELD_NUMBER: _ClassVar[int]
    sequence_num: int
    maps: _containers.RepeatedCompositeFieldContainer[DepthMap]
    def __init__(self, sequence_num: _Optional[int] = ..., maps: _Optional[_Iterable[_Union[DepthMap, _Mapping]]] = ...) -> None: ...

class SceneRequest(_message.Message):
    __slots__ = ("session_id",)
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    session_id: str
    def __init__(self, session_id: _Optional[str] = ...) -> None: ...

class Obstacle(_message.Message):
    __slots__ = ("kind", "x", "y", "heading", "length", "width")
    KIND_FIELD_NUMBER: _ClassVar[int]
    X_FIELD_NUMBER: _ClassVar[int]
    Y_FIELD_NUMBER: _ClassVar[int]
    HEADING_FIELD_NUMBER: _ClassVar[int]
    LENGTH_FIELD_NUMBER: _ClassVar[int]
    WIDTH_FIELD_NUMBER: _ClassVar[int]
    kind: str
    x: float
    y: float
    heading: float
    length: float
    width: float
    def __init__(self, kind: _Optional[str] = ..., x: _Optional[float] = ..., y: _Optional[float] = ..., heading: _Optional[float] = ..., length: _Optional[float] = ..., width: _Optional[float] = ...) -> None: ...

class SceneResponse(_message.Message):
    __slots__ = ("prompt", "seed", "centerline_x", "centerline_y", "road_half_width", "lanes", "obstacles", "ego_length", "ego_width", "lane_width")
    PROMPT_FIELD_NUMBER: _ClassVar[int]
    SEED_FIELD_NUMBER: _ClassVar[int]
    CENTERLINE_X_FIELD_NUMBER: _ClassVar[int]
    CENTERLINE_Y_FIELD_NUMBER: _ClassVar[int]
    ROAD_HALF_WIDTH_FIELD_NUMBER: _ClassVar[int]
    LANES_FIELD_NUMBER: _ClassVar[int]
    OBSTACLES_FIELD_NUMBER: _ClassVar[int]
    EGO_LENGTH_FIELD_NUMBER: _ClassVar[int]
    EGO_WIDTH_FIELD_NUMBER: _ClassVar[int]
    LANE_WIDTH_FIELD_NUMBER: _ClassVar[int]
    prompt: str
    seed: int
    centerline_x: _containers.RepeatedScalarFieldContainer[float]
    centerline_y: _containers.RepeatedScalarFieldContainer[float]
    road_half_width: float
    lanes: int
    obstacles: _containers.RepeatedCompositeFieldContainer[Obstacle]
    ego_length: float
    ego_width: float
    lane_width: float
    def __init__(self, prompt: _Optional[str] = ..., seed: _Optional[int] = ..., centerline_x: _Optional[_Iterable[float]] = ..., centerline_y: _Optional[_Iterable[float]] = ..., road_half_width: _Optional[float] = ..., lanes: _Optional[int] = ..., obstacles: _Optional[_Iterable[_Union[Obstacle, _Mapping]]] = ..., ego_length: _Optional[float] = ..., ego_width: _Optional[float] = ..., lane_width: _Optional[float] = ...) -> None: ...
