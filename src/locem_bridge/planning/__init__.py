"""Planning before the tool touches the wall: how an area is cut into pieces a raster can work (openings with
their frames left out), and -- next -- which parts of each joint and area the robot reaches from which base pose.
ROS-free."""
