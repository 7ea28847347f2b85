"""HICEM: the executive (ROS-free). Behavior trees loaded from XML, data store (HDM/HDICT), health monitor."""
