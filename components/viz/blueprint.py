"""The rerun blueprint of humanpt's view (live and ``humanpt view`` alike).

Left: the 3D world (robot flange, camera frustum, D, the filtered and measured target,
the recorded path as it grows, the twin's ground truth) over the event log and the
controller's status.  Right: the complex image with detected centres, pairs, expected,
desired and true source positions, over the time plots: tracking error, command, loop
latency, tracking (visible sources, quality, missed ALTER cycles), the servo's field-of-view
margin and the recorded path's uncertainty.  The time panel
follows the ``stamp`` timeline (the data's own time).
"""

from __future__ import annotations

import rerun.blueprint as rrb

__all__ = ["blueprint"]


def blueprint(*, picture: bool = False) -> rrb.Blueprint:
    """The view's layout; ``picture``: for a screenshot of a whole run (the side and time
    panels collapsed, the time cursor at the run's end)."""
    world = rrb.Spatial3DView(name="World (m)", origin="/world")
    image = rrb.Spatial2DView(name="Complex image", origin="/image")
    error = rrb.TimeSeriesView(name="Tracking error (mm, deg)", origin="/plots/error")
    command = rrb.TimeSeriesView(name="Command (mm/s, deg/s)", origin="/plots/command")
    latency = rrb.TimeSeriesView(name="Loop latency (ms)", origin="/plots/latency")
    tracking = rrb.TimeSeriesView(name="Sources, quality, misses", origin="/plots/tracking")
    servo = rrb.TimeSeriesView(name="Field of view margin, image offset (px)", origin="/plots/servo")
    path = rrb.TimeSeriesView(name="Path uncertainty (mm, deg)", origin="/plots/path")
    events = rrb.TextLogView(name="Events", origin="/events")
    status = rrb.TextDocumentView(name="Status", origin="/status")
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                world, rrb.Horizontal(events, status, column_shares=[3, 1]), row_shares=[3, 1]
            ),
            rrb.Vertical(
                image, error, command, rrb.Tabs(latency, tracking, servo, path), row_shares=[3, 2, 2, 2]
            ),
            column_shares=[1, 1],
        ),
        rrb.TimePanel(timeline="stamp", state="collapsed", play_state="following") if picture
        else rrb.TimePanel(timeline="stamp"),
        collapse_panels=picture,
    )
