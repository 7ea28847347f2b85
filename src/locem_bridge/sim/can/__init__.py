"""CANopen stand-ins of the mecanum base.

* :mod:`.drives`     four CiA 402 drives (canopen LocalNode) on a python-can bus, faults
* :mod:`.heartbeat`  drive heartbeats from a helper process (wall clock, outside the simulator's GIL)
"""
