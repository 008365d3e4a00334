"""The part found by a sparse first pass on the simulated rig: the dense scan sweeps only its
outline, searched at the heights the pass saw, and the whole region again when the part
reaches the outline's edge."""

import numpy as np
import shapely

from insitu.reconstruct.plan import scan_lines
from insitu.services import survey
from insitu.services.scan import scan_live
from insitu.services.station import connect


def test_the_scan_sweeps_the_outline_at_the_heights_the_survey_saw(monkeypatch):
    with connect(None, "step-block", 0, 4) as station:
        station.world.place_part((0.0, 0.0, 45.0))
        region = station.default_region()
        found = survey.survey_part(station, region, 4.0, 4.0)
        lo, hi = found.heights
        assert -3.5 < lo < 0.0 and 15.0 < hi < 18.5             # the table … the top step
        whole = scan_live(station, 2.0, region, room_light=False)
        assert len(scan_lines(region, 2.0)) == whole.summary.camera_frames
        camera, placed = station.devices.camera, []
        place = camera.set_region_of_interest
        monkeypatch.setattr(camera, "set_region_of_interest", lambda roi: placed.append(roi)
                            or place(roi))
        dense = scan_live(station, 2.0, region, within=found.outline, heights=found.heights,
                          room_light=False)
        windows = {(u1 - u0, v1 - v0) for u0, v0, u1, v1 in placed[1:-1]}
        assert len(placed) > dense.summary.frames and len(windows) == 1  # each its own window
        assert dense.summary.station_s < 0.6 * whole.summary.station_s  # the survey: 1/2 at
        assert found.station_s < 0.6 * whole.summary.station_s          # 2 mm, 1/8 at 0.5 mm
        top = [r.cloud.points[r.cloud.points[:, 2] > 0.5] for r in (dense, whole)]
        assert len(top[0]) > 0.95 * len(top[1])                 # the part as fully measured
        # an outline the part reaches beyond: the whole region is scanned again
        tight, wide = (np.asarray(shapely.Polygon(found.outline).buffer(d).exterior.coords)
                       for d in (-8.0, 8.0))
        assert survey.reaches_edge(whole.cloud.points, tight, 2.0)
        assert not survey.reaches_edge(whole.cloud.points, wide, 2.0)
        monkeypatch.setattr(survey, "survey_part", lambda *a: survey.Survey(
            tight, found.heights, 0.0))
        again = survey.scan_found(station, region, 4.0, 4.0, spacing=2.0, room_light=False)
        assert again.summary.frames == whole.summary.frames
