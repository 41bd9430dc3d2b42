"""The topology stage's settings: the single source of its defaults."""

from dataclasses import dataclass

from ...settings import check_settings, setting

__all__ = ["TopologySettings"]


@dataclass(frozen=True)
class TopologySettings:
    """How crossings are resolved and paths are joined (lengths in units of the radius r).

    Attributes
    ----------
    anchor_distance : float
        Least horizontal distance from a junction's centre to the branch points the cues
        compare; it grows for shallow crossings, whose strands overlap farther out.
    anchor_margin : float
        The branch points lie this far beyond where two strands of width 2 r crossing at the
        junction's smallest angle between branches stop overlapping.
    max_anchor_distance : float
        Greatest distance of the branch points from the junction's centre.
    height_window : float
        A branch's height is the mean height of its centreline within this arc length each way
        of its branch point (and on its own half of a segment between two junctions).
    bend_scale : float
        Turning angle (radians) of a strand through a junction that costs half a unit of
        log-likelihood: the bending cost is ``energy / (2 bend_scale**2)``.
    vertical_weight : float
        Heights count this much in the bending energy (the over strand's ramp is a real bend
        that the height cue already reads, and carving noise is largest along ``up``).
    height_scale : float
        Height difference between two crossing strands worth one unit of log-odds.
    height_cap : float
        The height cue gives one order at most twice this log-odds over the other.
    image_gain : float
        Log-odds per unit of the image cue's statistic: the views' weighted mean score over its
        standard error (a t statistic).
    image_spread : float
        Least standard deviation of the view scores assumed by that statistic.
    image_prior_views : float
        The statistic shrinks by ``n / (n + image_prior_views)`` for ``n`` effective views: one
        or two views that happen to agree closely are not taken as certain.
    image_cap : float
        The image cue gives one order at most twice this log-odds over the other.
    top_down_power : float
        A view weighs ``cos(zenith angle) ** top_down_power``: views straight down count most.
    min_pixel_radius : float
        Views where the cable's radius is below this many pixels are not used; the weight grows
        to 1 over the next two pixels.
    occluder_margin : float
        A view is not used for a junction when another part of the cable, nearer the camera,
        projects within this many projected radii (plus one) of the paths between its branch
        points and centre.
    highlight_search : float
        A projected branch point moves to the brightest cable pixel within this many projected
        radii (the paper's answer to specular highlights: a path starting on a highlight
        follows it along the cable).
    highlight_clip : float
        Before the gradient is taken, each colour channel is clipped at this quantile of its
        values on the cable's pixels, so the edges of specular highlights cost nothing.
    edge_scale : float
        A pixel costs ``edge_floor + g**2 / edge_scale`` for a gradient magnitude ``g`` (8-bit
        levels per pixel, the largest over the colour channels): squaring makes the few strong
        occlusion edges count more than many weak ripples of shading and noise.
    edge_floor : float
        Cost of every pixel: paths are short as well as smooth, and a view of noise scores near
        zero.
    path_radius : float
        The paths are found where the cable's radius is at most this many pixels: a view that
        shows it larger is reduced around the junction first (the cost of the paths grows
        with the square of the patch's side; the edges they weigh are as clear).
    spur_length : float
        At a junction with an odd number of branches or more than four, a branch to a free end
        shorter than this may be a spur of carving noise (or a stub of cable): it may stay
        unpaired, and a piece made of it alone is dropped.
    unpaired_cost : float
        Log-likelihood cost of leaving a branch that is not such a spur unpaired, and gain of
        leaving a spur unpaired.
    gap_length : float
        A junction with an odd number of branches and no spur (one branch was missed by the
        carving) is joined to a free end within this horizontal distance whose cable heads
        towards it: the gap is bridged straight.
    bigon_length : float
        A segment up to this long between two junctions that each miss a branch is taken for
        two strands lying together between two crossings, and doubled (0: never).
    end_crossing_height : float
        A junction's one unpaired branch (not a spur) beside one strand, this much higher or
        lower than the strand, crosses over or under it (a cable end lying across the strand,
        or a branch the carving missed): its path goes on through the junction (0: never; it
        ends there).
    end_crossing_reach : float
        How far beyond the junction's centre such an end goes.
    min_path_length : float
        Paths shorter than this (specks of carving noise) are dropped, unless nothing else is
        left.
    bridge_distance : float
        Branches are cut this far (horizontally) from the junction's centre and joined by a
        smooth bridge.
    separation : float
        Vertical distance between the over and the under strand that the bridges are given.
    lift_width : float
        Half width (horizontal arc length) of the bump that lifts or lowers a strand there.
    confident : float
        Crossings less sure than this are reported with a warning.
    max_degree : int
        Junctions with more branches are paired greedily by bending.
    search_budget : int
        Largest number of combinations of matchings the one-path search tries per cable (when
        one makes the cable one path it comes early in the hard tuning heaps, looked at in
        script runs; the whole budget is spent only where none does).
    search_window : float
        Having found the most likely combination that makes each cable one path, the search
        weighs the others up to this many log-units less likely (each then weighs under
        e^-window of it) into every junction's probability.
    """

    anchor_distance: float = setting(3.0, above=0, unit="r")
    anchor_margin: float = setting(1.5, low=0, unit="r")
    max_anchor_distance: float = setting(7.0, above=0, unit="r")
    height_window: float = setting(1.5, above=0, unit="r")
    bend_scale: float = setting(0.5, above=0, unit="rad")
    vertical_weight: float = setting(0.3, low=0)
    height_scale: float = setting(0.4, above=0, unit="r")
    height_cap: float = setting(3.0, low=0)
    image_gain: float = setting(0.5, above=0)
    image_spread: float = setting(0.1, above=0)
    image_prior_views: float = setting(3.0, low=0, unit="views")
    image_cap: float = setting(3.0, low=0)
    top_down_power: float = setting(2.0, low=0)
    min_pixel_radius: float = setting(1.5, low=0, unit="px")
    occluder_margin: float = setting(1.5, low=0, unit="r")
    highlight_search: float = setting(0.7, above=0)
    highlight_clip: float = setting(0.8, above=0, high=1)
    edge_scale: float = setting(10.0, above=0)
    edge_floor: float = setting(1.0, low=0)
    path_radius: float = setting(3.0, above=0, unit="px")
    spur_length: float = setting(15.0, low=0, unit="r")
    unpaired_cost: float = setting(4.0, low=0)
    gap_length: float = setting(10.0, low=0, unit="r")
    bigon_length: float = setting(30.0, low=0, unit="r")
    end_crossing_height: float = setting(0.5, low=0, unit="r")
    end_crossing_reach: float = setting(3.0, above=0, unit="r")
    min_path_length: float = setting(10.0, low=0, unit="r")
    bridge_distance: float = setting(2.5, above=0, unit="r")
    separation: float = setting(2.2, low=0, unit="r")
    lift_width: float = setting(4.0, above=0, unit="r")
    confident: float = setting(0.9, low=0, high=1)
    max_degree: int = setting(8, low=2)
    search_budget: int = setting(2000, low=1)
    search_window: float = setting(9.0, low=0)

    def __post_init__(self):
        check_settings(self)
