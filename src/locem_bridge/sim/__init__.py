"""The simulated worksite: a PyBullet plasterboard site and protocol-level device stand-ins (RTDE, Modbus, CANopen)."""
