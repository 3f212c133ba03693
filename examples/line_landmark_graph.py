"""A robot drives around a small room and maps its four walls as line landmarks, in plain GTSAM.

The same story as GTSAM's ``PlanarSLAMExample.py``, with walls instead of point landmarks.
Each wall is a landmark in the anchored chart of :mod:`slam.models.anchored`: a fixed anchor
point ``c`` on the wall and the value ``(ρ, φ)`` stored as a ``gtsam.Point2``, the line
``{p : (p − c)·(cos φ, sin φ) = ρ}``.  A measurement is the wall's ``(r, α)`` in the robot's
frame (the paper's Eq. 30, :func:`slam.geometry.predict_line_measurement`), and the project's
line factor (:func:`slam.graph.custom_factor.line_custom_factor`, a ``gtsam.CustomFactor``)
ties a pose to a wall.  Run it with ``python examples/line_landmark_graph.py``.
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, X

from slam.graph.custom_factor import line_custom_factor
from slam.models.anchored import r_alpha_from_anchored

# Create noise models: standard deviations in metres and radians.  The prior pins the map
# frame to where the robot starts; odometry is poor; a wall's (r, α) is measured well.
PRIOR_NOISE = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.01, 0.01, 0.005]))
ODOMETRY_NOISE = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.2, 0.2, 0.1]))
LINE_NOISE = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.02, 0.01]))

# The room, 6 m by 4 m around the origin: each wall as (r, α), its anchor at its mid-point.
WALLS = np.array([[3.0, 0.0], [2.0, np.pi / 2], [3.0, np.pi], [2.0, -np.pi / 2]])
ANCHORS = np.array([[3.0, 0.0], [0.0, 2.0], [-3.0, 0.0], [0.0, -2.0]])

# The robot's true path: four corners of a rectangle, turning left by 90° at each.
TRUE_POSES = [
    gtsam.Pose2(-1.5, -1.0, 0.0),
    gtsam.Pose2(1.5, -1.0, np.pi / 2),
    gtsam.Pose2(1.5, 1.0, np.pi),
    gtsam.Pose2(-1.5, 1.0, -np.pi / 2),
]


def seen_from(wall: np.ndarray, pose: gtsam.Pose2) -> np.ndarray:
    """The wall ``(r, α)`` (world) as the robot at ``pose`` sees it: ``(r, α)`` in its frame.

    Eq. 30 inverted: ``r' = r − x cos α − y sin α``, ``α' = α − θ``, in normal form (``r' ≥ 0``).
    """
    r, alpha = wall
    r_robot = r - pose.x() * np.cos(alpha) - pose.y() * np.sin(alpha)
    alpha_robot = alpha - pose.theta()
    if r_robot < 0.0:
        r_robot, alpha_robot = -r_robot, alpha_robot + np.pi
    return np.array([r_robot, np.arctan2(np.sin(alpha_robot), np.cos(alpha_robot))])


def main(seed: int = 20030514, verbose: bool = True) -> dict[str, object]:
    """Build the graph, optimise it and print the poses and walls with their covariances.

    Parameters
    ----------
    seed
        Seed of the simulated odometry and line measurement noise.
    verbose
        Print the story (the test runs it quietly).

    Returns
    -------
    dict
        ``graph``, ``initial`` and ``result`` (``gtsam.Values``), ``marginals``,
        ``initial_error`` and ``final_error`` (the graph's error, half the sum of squared
        whitened residuals).
    """
    rng = np.random.default_rng(seed)

    # Create an empty nonlinear factor graph.
    graph = gtsam.NonlinearFactorGraph()

    # Add a prior on the first pose, setting it to where the robot starts.
    graph.add(gtsam.PriorFactorPose2(X(1), TRUE_POSES[0], PRIOR_NOISE))

    # Add odometry factors: the true motion between poses, with noise drawn from the model.
    for i in range(1, len(TRUE_POSES)):
        motion = TRUE_POSES[i - 1].between(TRUE_POSES[i])
        noisy = motion.compose(gtsam.Pose2.Expmap(rng.normal(0.0, ODOMETRY_NOISE.sigmas())))
        graph.add(gtsam.BetweenFactorPose2(X(i), X(i + 1), noisy, ODOMETRY_NOISE))

    # Add line measurements: from every pose the robot sees all four walls.  The factor takes
    # the wall's anchor, the measured (r, α), its covariance and (here) the noise model itself.
    line_cov = np.diag(LINE_NOISE.sigmas() ** 2)
    for i, pose in enumerate(TRUE_POSES, start=1):
        for j, (wall, anchor) in enumerate(zip(WALLS, ANCHORS, strict=True), start=1):
            z = seen_from(wall, pose) + rng.normal(0.0, LINE_NOISE.sigmas())
            graph.add(line_custom_factor(X(i), L(j), anchor, z, line_cov, noise=LINE_NOISE))

    # Create the initial estimate, deliberately off: poses a few decimetres and degrees away,
    # each wall ρ = 0.3 m off its anchor and turned by 0.1 rad.
    initial = gtsam.Values()
    for i, pose in enumerate(TRUE_POSES, start=1):
        off = gtsam.Pose2(0.3 * (-1) ** i, -0.2, 0.1 * (-1) ** i)
        initial.insert(X(i), pose.compose(off))
    for j, wall in enumerate(WALLS, start=1):
        initial.insert(L(j), gtsam.Point2(0.3, wall[1] + 0.1))

    # Optimise with Levenberg-Marquardt.
    params = gtsam.LevenbergMarquardtParams()
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    initial_error, final_error = graph.error(initial), graph.error(result)

    # Calculate and print the marginal covariances of all the variables.
    marginals = gtsam.Marginals(graph, result)
    if verbose:
        print(f"{graph.size()} factors; error {initial_error:.1f} -> {final_error:.2f}")
        with np.printoptions(precision=2):
            for i, true_pose in enumerate(TRUE_POSES, start=1):
                pose = result.atPose2(X(i))
                print(f"\nX{i} = ({pose.x():.3f}, {pose.y():.3f}, {pose.theta():.4f})", end="")
                print(f", truth ({true_pose.x()}, {true_pose.y()}, {true_pose.theta():.4f})")
                print(f"covariance of (x, y, θ), body frame:\n{marginals.marginalCovariance(X(i))}")
            for j, (wall, anchor) in enumerate(zip(WALLS, ANCHORS, strict=True), start=1):
                r, alpha = r_alpha_from_anchored(np.asarray(result.atPoint2(L(j))), anchor)
                print(f"\nL{j}: (r, α) = ({r:.4f}, {alpha:.4f}), truth ({wall[0]}, {wall[1]:.4f})")
                print(f"covariance of (ρ, φ):\n{marginals.marginalCovariance(L(j))}")
    return {
        "graph": graph,
        "initial": initial,
        "result": result,
        "marginals": marginals,
        "initial_error": initial_error,
        "final_error": final_error,
    }


if __name__ == "__main__":
    main()
