from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class ErrorCode(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    ERROR_CODE_UNSPECIFIED: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_SESSION: _ClassVar[ErrorCode]
    ERROR_CODE_ALREADY_FINISHED: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_REQUEST: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_MODEL: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_FORMAT: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_ENVIRONMENTS: _ClassVar[ErrorCode]
    ERROR_CODE_PROMPT_SET: _ClassVar[ErrorCode]
    ERROR_CODE_UNSUPPORTED_SDK_VERSION: _ClassVar[ErrorCode]
    ERROR_CODE_INVALID_API_KEY: _ClassVar[ErrorCode]

class FrameFormat(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    FRAME_FORMAT_UNSPECIFIED: _ClassVar[FrameFormat]
    FRAME_FORMAT_JPEG: _ClassVar[FrameFormat]
    FRAME_FORMAT_H264: _ClassVar[FrameFormat]
    FRAME_FORMAT_VP9: _ClassVar[FrameFormat]
    FRAME_FORMAT_VP8: _ClassVar[FrameFormat]
    FRAME_FORMAT_RAW_YUV420: _ClassVar[FrameFormat]
ERROR_CODE_UNSPECIFIED: ErrorCode
ERROR_CODE_INVALID_SESSION: ErrorCode
ERROR_CODE_ALREADY_FINISHED: ErrorCode
ERROR_CODE_INVALID_REQUEST: ErrorCode
ERROR_CODE_INVALID_MODEL: ErrorCode
ERROR_CODE_INVALID_FORMAT: ErrorCode
ERROR_CODE_INVALID_ENVIRONMENTS: ErrorCode
ERROR_CODE_PROMPT_SET: ErrorCode
ERROR_CODE_UNSUPPORTED_SDK_VERSION: ErrorCode
ERROR_CODE_INVALID_API_KEY: ErrorCode
FRAME_FORMAT_UNSPECIFIED: FrameFormat
FRAME_FORMAT_JPEG: FrameFormat
FRAME_FORMAT_H264: FrameFormat
FRAME_FORMAT_VP9: FrameFormat
FRAME_FORMAT_VP8: FrameFormat
FRAME_FORMAT_RAW_YUV420: FrameFormat

class Error(_message.Message):
    __slots__ = ("code", "message", "details")
    class DetailsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: str
        def __init__(self, key: _Optional[str] = ..., value: _Optional[str] = ...) -> None: ...
    CODE_FIELD_NUMBER: _ClassVar[int]
    MESSAGE_FIELD_NUMBER: _ClassVar[int]
    DETAILS_FIELD_NUMBER: _ClassVar[int]
    code: ErrorCode
    message: str
    details: _containers.ScalarMap[str, str]
    def __init__(self, code: _Optional[_Union[ErrorCode, str]] = ..., message: _Optional[str] = ..., details: _Optional[_Mapping[str, str]] = ...) -> None: ...
