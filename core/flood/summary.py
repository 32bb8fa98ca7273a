"""A flood's report in the words a modeller reads, for the command line and for QGIS's log
(QGIS's own Python imports this: the standard library only)."""


def time_step_summary(report: dict) -> str:
    """Where a flood's time step was set most, in one line ("" if nowhere): the place a
    modeller looks at to make the flood cheaper (a sliver, a line end, a fast jet)."""
    found = report.get("time_step_set_by") or []
    if not found:
        return ""
    k = found[0]
    return (f"time step set most by the triangle at ({k['x']:.1f}, {k['y']:.1f}) (inradius "
            f"{k['inradius_m']:.2f} m, max depth {k['max_depth_m']:.2f} m, max speed "
            f"{k['max_speed_ms']:.2f} m/s): {100 * k['share_of_steps']:.0f} % of the steps")
