from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Channel(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    CHANNEL_UNSPECIFIED: _ClassVar[Channel]
    CHANNEL_UV: _ClassVar[Channel]
    CHANNEL_EV: _ClassVar[Channel]
    CHANNEL_BIPOLAR: _ClassVar[Channel]

class Locking(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    LOCKING_UNSPECIFIED: _ClassVar[Locking]
    LOCKING_POSITION: _ClassVar[Locking]
    LOCKING_VELOCITY: _ClassVar[Locking]
    LOCKING_AUTO: _ClassVar[Locking]

class Domain(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    DOMAIN_UNSPECIFIED: _ClassVar[Domain]
    DOMAIN_SPATIAL: _ClassVar[Domain]
    DOMAIN_TEMPORAL: _ClassVar[Domain]
CHANNEL_UNSPECIFIED: Channel
CHANNEL_UV: Channel
CHANNEL_EV: Channel
CHANNEL_BIPOLAR: Channel
LOCKING_UNSPECIFIED: Locking
LOCKING_POSITION: Locking
LOCKING_VELOCITY: Locking
LOCKING_AUTO: Locking
DOMAIN_UNSPECIFIED: Domain
DOMAIN_SPATIAL: Domain
DOMAIN_TEMPORAL: Domain

class Card(_message.Message):
    __slots__ = ("version", "metadata", "surface", "grid", "textures")
    VERSION_FIELD_NUMBER: _ClassVar[int]
    METADATA_FIELD_NUMBER: _ClassVar[int]
    SURFACE_FIELD_NUMBER: _ClassVar[int]
    GRID_FIELD_NUMBER: _ClassVar[int]
    TEXTURES_FIELD_NUMBER: _ClassVar[int]
    version: FormatVersion
    metadata: Metadata
    surface: Surface
    grid: TaxtelGrid
    textures: _containers.RepeatedCompositeFieldContainer[Texture]
    def __init__(self, version: _Optional[_Union[FormatVersion, _Mapping]] = ..., metadata: _Optional[_Union[Metadata, _Mapping]] = ..., surface: _Optional[_Union[Surface, _Mapping]] = ..., grid: _Optional[_Union[TaxtelGrid, _Mapping]] = ..., textures: _Optional[_Iterable[_Union[Texture, _Mapping]]] = ...) -> None: ...

class FormatVersion(_message.Message):
    __slots__ = ("major", "minor")
    MAJOR_FIELD_NUMBER: _ClassVar[int]
    MINOR_FIELD_NUMBER: _ClassVar[int]
    major: int
    minor: int
    def __init__(self, major: _Optional[int] = ..., minor: _Optional[int] = ...) -> None: ...

class Metadata(_message.Message):
    __slots__ = ("title", "author", "licence", "generator", "description")
    TITLE_FIELD_NUMBER: _ClassVar[int]
    AUTHOR_FIELD_NUMBER: _ClassVar[int]
    LICENCE_FIELD_NUMBER: _ClassVar[int]
    GENERATOR_FIELD_NUMBER: _ClassVar[int]
    DESCRIPTION_FIELD_NUMBER: _ClassVar[int]
    title: str
    author: str
    licence: str
    generator: str
    description: str
    def __init__(self, title: _Optional[str] = ..., author: _Optional[str] = ..., licence: _Optional[str] = ..., generator: _Optional[str] = ..., description: _Optional[str] = ...) -> None: ...

class Surface(_message.Message):
    __slots__ = ("width_mm", "height_mm")
    WIDTH_MM_FIELD_NUMBER: _ClassVar[int]
    HEIGHT_MM_FIELD_NUMBER: _ClassVar[int]
    width_mm: float
    height_mm: float
    def __init__(self, width_mm: _Optional[float] = ..., height_mm: _Optional[float] = ...) -> None: ...

class TaxtelGrid(_message.Message):
    __slots__ = ("taxtel_width_mm", "taxtel_height_mm", "cols", "rows", "texture_index")
    TAXTEL_WIDTH_MM_FIELD_NUMBER: _ClassVar[int]
    TAXTEL_HEIGHT_MM_FIELD_NUMBER: _ClassVar[int]
    COLS_FIELD_NUMBER: _ClassVar[int]
    ROWS_FIELD_NUMBER: _ClassVar[int]
    TEXTURE_INDEX_FIELD_NUMBER: _ClassVar[int]
    taxtel_width_mm: float
    taxtel_height_mm: float
    cols: int
    rows: int
    texture_index: _containers.RepeatedScalarFieldContainer[int]
    def __init__(self, taxtel_width_mm: _Optional[float] = ..., taxtel_height_mm: _Optional[float] = ..., cols: _Optional[int] = ..., rows: _Optional[int] = ..., texture_index: _Optional[_Iterable[int]] = ...) -> None: ...

class Texture(_message.Message):
    __slots__ = ("name", "baseline", "channel", "locking", "components")
    NAME_FIELD_NUMBER: _ClassVar[int]
    BASELINE_FIELD_NUMBER: _ClassVar[int]
    CHANNEL_FIELD_NUMBER: _ClassVar[int]
    LOCKING_FIELD_NUMBER: _ClassVar[int]
    COMPONENTS_FIELD_NUMBER: _ClassVar[int]
    name: str
    baseline: float
    channel: Channel
    locking: Locking
    components: _containers.RepeatedCompositeFieldContainer[Component]
    def __init__(self, name: _Optional[str] = ..., baseline: _Optional[float] = ..., channel: _Optional[_Union[Channel, str]] = ..., locking: _Optional[_Union[Locking, str]] = ..., components: _Optional[_Iterable[_Union[Component, _Mapping]]] = ...) -> None: ...

class Component(_message.Message):
    __slots__ = ("domain", "frequency", "amplitude", "phase", "orientation", "channel")
    DOMAIN_FIELD_NUMBER: _ClassVar[int]
    FREQUENCY_FIELD_NUMBER: _ClassVar[int]
    AMPLITUDE_FIELD_NUMBER: _ClassVar[int]
    PHASE_FIELD_NUMBER: _ClassVar[int]
    ORIENTATION_FIELD_NUMBER: _ClassVar[int]
    CHANNEL_FIELD_NUMBER: _ClassVar[int]
    domain: Domain
    frequency: float
    amplitude: float
    phase: float
    orientation: float
    channel: Channel
    def __init__(self, domain: _Optional[_Union[Domain, str]] = ..., frequency: _Optional[float] = ..., amplitude: _Optional[float] = ..., phase: _Optional[float] = ..., orientation: _Optional[float] = ..., channel: _Optional[_Union[Channel, str]] = ...) -> None: ...
