"""Shared by the UR stand-in tests that drive it with the real ur_rtde clients."""
import time

Q_HOME = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]


def disconnect_all(*clients):
    """Disconnect every ur_rtde client given, ignoring the ones already gone."""
    for c in clients:
        try:
            c.disconnect()
        except Exception:
            pass


def eventually(fn, timeout=3.0):
    """Poll ``fn`` until it returns a true value (the receive stream is another connection: it may lag a few
    cycles behind the control connection, more so on a loaded machine); its last value after ``timeout`` s."""
    end = time.time() + timeout
    while True:
        value = fn()
        if value or time.time() > end:
            return value
        time.sleep(0.005)
