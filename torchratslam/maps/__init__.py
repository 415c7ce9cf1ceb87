"""Saved maps: the in-memory map state, the native and the authors' reference formats, merges."""

from torchratslam.maps.compat import check_compatible
from torchratslam.maps.io import convert_map, load_state, map_format, reference_losses
from torchratslam.maps.merge import (
    MergeResult,
    first_experience,
    merge_maps,
    pc_distance,
    pick_experience,
    shift_activity,
)
from torchratslam.maps.native import FORMAT_NAME, FORMAT_VERSION, load_map, save_map
from torchratslam.maps.reference_format import (
    FILES,
    is_reference_map,
    read_reference,
    write_reference,
)
from torchratslam.maps.running import save_state
from torchratslam.maps.state import MapState

__all__ = [
    "FILES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MapState",
    "MergeResult",
    "check_compatible",
    "convert_map",
    "first_experience",
    "is_reference_map",
    "load_map",
    "load_state",
    "map_format",
    "merge_maps",
    "pc_distance",
    "pick_experience",
    "read_reference",
    "reference_losses",
    "save_map",
    "save_state",
    "shift_activity",
    "write_reference",
]
