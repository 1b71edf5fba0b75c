"""schemas.convert.message_field: a field of a message by its dotted path (humanpt echo
--field), with list indices and enum names; a path that is not there names the part."""

from __future__ import annotations

import pytest

from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import MessageError, header, message_field, message_stamp_ns


def _tob() -> pb.TobMeasurement:
    m = pb.TobMeasurement(header=header(123_456, 7, "camera"), status=pb.TOB_STATUS_POSITION_ONLY, visible=2)
    m.pairs.add(right=1, left=4, residual_px=0.25)
    m.pairs.add(right=2, left=5, residual_px=0.5)
    m.camera_T_tob.translation.x = 0.6
    m.degraded_sources.extend([0, 2])
    return m


def test_fields_by_path_with_indices_and_enum_names():
    m = _tob()
    assert message_field(m, "header.seq") == 7
    assert message_field(m, "camera_T_tob.translation.x") == 0.6
    assert message_field(m, "pairs[1].residual_px") == 0.5
    assert message_field(m, "status") == "TOB_STATUS_POSITION_ONLY"
    assert message_field(m, "degraded_sources") == [0, 2]
    assert message_field(m, "pairs[0]") == "right: 1 left: 4 residual_px: 0.25"
    assert message_stamp_ns(m) == 123_456


@pytest.mark.parametrize("path, fragment", [
    ("nope", "has no field 'nope'"),
    ("header.nope", "humanpt.TobMeasurement.header has no field 'nope'"),
    ("pairs[2].left", "has 2 entries, no [2]"),
    ("visible[0]", "is not a list"),
    ("header.seq.x", "'x' is not a field"),
    ("pairs[x]", "'pairs[x]' is not a field"),
])
def test_a_path_that_is_not_there_names_the_part(path, fragment):
    with pytest.raises(MessageError) as e:
        message_field(_tob(), path)
    assert fragment in str(e.value)
