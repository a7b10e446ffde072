"""The model of the Butterfly robot rig: pure numpy and scipy, no rclpy.

Parameters and parameter files (:mod:`.params`, :mod:`.param_file`), the exact offset-curve
geometry (:mod:`.geometry`), the rigid dynamics and its compiled kernels (:mod:`.dynamics`,
:mod:`.layout`, :mod:`.integrators`, :mod:`.simulate`), the perturbations of the seed's study
(:mod:`.perturbations`), the force-based contact model (:mod:`.contact`,
:mod:`.closest_point`), and recordings with their readers and writers (:mod:`.recording`,
:mod:`.io`: rig logs, CSV, ROS 2 bags).
"""
