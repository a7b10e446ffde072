"""An independent Butterfly rig (physics, controllers, sensors, logs, ROS 2 stand-in).

Written apart from bfr to prove bfr on truth it did not make; see README.md here.
"""
