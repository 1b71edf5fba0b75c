"""A rerun blueprint for a merged run converted by rerun's own MCAP import.

rerun (0.41) turns ``scene/transforms`` into named-frame ``Transform3D`` rows and
``scene/path`` into ``InstancePoses3D``, which the viewer draws only with a
``TransformAxes3D`` visualizer; ``scene/path_points`` (Points3D in frame ``world``) and the
camera's ``Pinhole`` need the 3D view to look from the ``world`` frame.  This blueprint sets
both, so::

    humanpt runs merge RUN run.mcap
    rerun mcap convert run.mcap --application-id humanpt-run -o run.rrd
    python -m humanpt.scene.rerun_blueprint run.rbl
    rerun run.rbl run.rrd

(the blueprint first: rerun 0.41 then applies it to the recording) shows the frames, the path, the image and the log.  (The live view is ``humanpt view`` /
viz; this is for the MCAP as any rerun user opens it.)
"""

from __future__ import annotations

import argparse
import sys

from humanpt.schemas import topics

__all__ = ["blueprint", "main"]

APPLICATION_ID = "humanpt-run"


def blueprint(cell: str = "cell0"):
    """The blueprint (rerun.blueprint.Blueprint) for the channels of ``cell``."""
    import rerun as rr
    import rerun.blueprint as rrb

    def entity(short: str) -> str:
        return "/" + topics.TOPICS[short].key(cell)

    view3d = rrb.Spatial3DView(
        name="cell (world)", origin="/", contents=[entity("scene/transforms"), entity("scene/path"),
                                                   entity("scene/path_points"), entity("scene/calibration"),
                                                   entity("camera/image")],
        spatial_information=rrb.archetypes.SpatialInformation(target_frame="world", show_axes=True),
        # The cell is metres from the world's origin: look at the recorded path.
        eye_controls=rrb.archetypes.EyeControls3D(tracking_entity=entity("scene/path_points")),
        overrides={entity("scene/transforms"): [rr.TransformAxes3D(axis_length=0.05, show_frame=True).visualizer()],
                   entity("scene/path"): [rr.TransformAxes3D(axis_length=0.01).visualizer()],
                   entity("scene/path_points"): [rr.Points3D.from_fields(radii=0.003,
                                                                         colors=[255, 230, 40]).visualizer()]})
    return rrb.Blueprint(rrb.Horizontal(
        view3d,
        rrb.Vertical(rrb.Spatial2DView(name="complex image", origin=entity("camera/image")),
                     rrb.TextLogView(name="log", origin=entity("scene/log"))),
        column_shares=[3, 2]))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m humanpt.scene.rerun_blueprint",
                                description="Write a rerun blueprint (.rbl) for a merged run converted with "
                                            "`rerun mcap convert --application-id humanpt-run`.")
    p.add_argument("out", help="the .rbl file to write (refused if it exists)")
    p.add_argument("--cell", default="cell0", help="the run's cell (default cell0; the live demo's: demo)")
    p.add_argument("--application-id", default=APPLICATION_ID,
                   help=f"the converted recording's application id (default {APPLICATION_ID})")
    args = p.parse_args(argv)
    from pathlib import Path

    out = Path(args.out)
    if out.exists():
        print(f"{out}: exists; not overwritten", file=sys.stderr)
        return 1
    blueprint(args.cell).save(args.application_id, str(out))
    print(f"wrote {out}: rerun {out} RUN.rrd")
    return 0


if __name__ == "__main__":
    sys.exit(main())
