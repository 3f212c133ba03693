"""Figures (matplotlib, Agg backend); imported only inside the functions that draw a picture.

One module per kind of figure, the shapes they share drawn once:

* :mod:`slam.plotting.shapes` — covariance ellipses of points, uncertainty bands of lines,
  line segments (the geometry in numpy, added to axes as matplotlib collections);
* :mod:`slam.plotting.scan` — one scan and its fitted lines (the paper's Fig. 3);
* :mod:`slam.plotting.map` — the paper's panels A/B/C of map building (raw points, fitted
  lines, merged lines);
* :mod:`slam.plotting.trajectory_map` — a SLAM result's trajectory over its line map;
* :mod:`slam.plotting.compare` — curves of the comparison and consistency experiments
  (trajectories, errors, NEES, run time over scans).

Every figure function writes one file and returns its path (:mod:`slam.plotting.figure`);
none opens a window.  Nothing in :mod:`linefit` or the algorithmic layers of :mod:`slam`
imports this package.
"""
