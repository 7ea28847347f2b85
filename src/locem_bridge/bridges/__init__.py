"""Device backends behind LOCEM: UR arm over RTDE, compressor over Modbus TCP, mobile base over CAN (CiA 402)."""
