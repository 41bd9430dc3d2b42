"""Crossings and one path per cable (paper §3.5, and beyond it).

The segment graph (:mod:`engine.stages.segment_graph`) says where the cable meets itself
(junctions) and which pieces of cable (segments) leave each junction, but not which branch
continues into which, nor which strand lies on top. This package decides both and joins the
segments into ordered centrelines: one path per cable, with the crossings listed (which strand is
over, how sure).

Method
------
At every junction each way of pairing its branches into strands that go through it (a
*matching*), together with an over/under order for every two strands that cross there (their
branches alternate around the junction), is a *hypothesis*. Its score is a sum of log-likelihood
terms from independent cues:

* **Bending** (continuity, the paper's implicit assumption): a strand goes straight through.
  The two branch points of a strand (on its centreline just beyond where the strands overlap)
  are joined by a cubic Hermite curve along their tangents; its dimensionless bending energy
  ``L * integral(kappa**2 ds)`` (the squared turning angle for a circular arc) costs
  ``energy / (2 bend_scale**2)``.
* **Height** (beyond the paper): the carved cable is higher where it passes over. The height
  along ``up`` of each branch's centreline next to its branch point is averaged per strand; the
  difference, over ``height_scale``, is the log-odds that the higher strand is over.
* **Images** (the paper's cue, voted over every view that sees the junction instead of one):
  the strand on top shows no edge across the junction, the one below shows two occlusion
  edges. In each view the branch points are projected, moved to the brightest cable pixel
  nearby, and joined by shortest paths (Dijkstra on a small patch) whose pixels cost
  ``edge_floor + g**2 / edge_scale`` for the colour gradient ``g``; off the cable mask they
  cost much more. Before the gradient is taken the brightest cable pixels are clipped, so a
  specular highlight makes no edge. For crossing strands ``O`` over ``U`` a view scores
  ``(c_U - c_O) / (c_U + c_O)``, ``c`` the path cost between a strand's two branch points.
  Views weigh by how straight down they look at the junction, by the largest angle between
  the projected branches and by the cable's size in pixels (and half where the view's junction
  map shows no junction there); views where another part of the cable, nearer the camera,
  crosses the paths are left out. The cue's log-odds is ``image_gain`` times the weighted
  t statistic of the view scores, shrunk when the views are few.

Each cue is capped, so that no single cue can make a crossing certain, and when the heights and
the images disagree the weaker one counts twice: the confidence then drops towards one half. A
junction's hypotheses get probabilities from their scores (softmax). A crossing's confidence is
the probability of its matching (given the one-path check below) times that of its order.

How often each crossing comes out right, and how sure, is measured by ``python -m engine bench
topology`` (easy and hard layouts, tuning and held-out seeds, the Cycles captures; README,
*Hard topology, measured*).

Paths: the segments are followed through the junctions along the chosen matchings. Each strand's
branches are cut ``bridge_distance`` from the junction (the carved centreline bends into the
junction's middle there) and joined by a smooth Hermite bridge; where two strands cross, the
over strand is lifted and the under one lowered by a smooth bump until they are ``separation``
apart, so the geometry says over and under as the crossing list does, and each crossing's
indices point at the two strands' closest pass. The paper's combinatorial check comes after: a
connected piece of the graph must give one path (open between two free ends, or closed), or
as few as its free ends allow. If the best matchings give more, the least confident junctions
are revisited first (a best-first search over combinations of matchings ranked by
probability), and the probabilities are conditioned on the check. Several connected pieces give
several paths (several cables).

Imperfect graphs (the pipeline has already followed the core's free ends through the hull to
the junctions missing a branch, :mod:`engine.stages.core_ends`; what is left comes here): a
short branch to a free end at a junction with an odd number of branches (or more than four)
may be a spur of carving noise: it may stay unpaired, and is then dropped; a junction with an
odd number of branches and no spur, near a free end whose cable heads towards it, has lost a
branch: the gap is bridged. Two such junctions joined by a short segment
(``bigon_length``) are two crossings of a twist whose strands lie together between them:
the segment is doubled, its copies a radius either side. Degree 2 junctions are passed
through, degree 3 junctions join their straightest two branches and end the third: at the
strand, or, where it lies ``end_crossing_height`` above or below the strand, a few radii past
it, crossing it (a cable end lying across a strand, its stub beyond too short for the
carving, which removes short dead ends; or a branch the carving missed), junctions
of more than ``max_degree`` branches are paired greedily by bending, and paths shorter than
``min_path_length`` are dropped; each gives a warning.

Modules, in the order the stage runs them: ``context`` (the inputs made ready: gaps closed,
twists doubled), ``junctions`` (hypotheses scored by bending and heights), ``image_cue`` (the
views' vote), ``one_path`` (the combinatorial check), ``assembly`` (the paths built);
``resolve`` runs them, ``settings`` and ``model`` hold what goes in and comes out, ``polylines``
the curve helpers they share.
"""

from .model import Topology, TopologyCrossing, TopologyPath, TopologyView
from .resolve import resolve_topology
from .settings import TopologySettings

__all__ = ["TopologySettings", "TopologyView", "TopologyPath", "TopologyCrossing", "Topology",
           "resolve_topology"]
