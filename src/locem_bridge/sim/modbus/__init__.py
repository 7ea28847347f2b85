"""Modbus TCP stand-in of the spray compressor.

* :mod:`.compressor`     pressure model + Modbus register map (plain Python)
* :mod:`.modbus_server`  compressor Modbus TCP server for the installed pymodbus (3.16 or 3.6), link-drop faults
* :mod:`.modbus_base`    shared lifecycle and link faults; :mod:`.modbus_legacy` the pymodbus 3.6 adapter
  (Python 3.8 / Noetic)
"""
