"""The Katana 300 6M180 on the Pioneer: its serial protocol, the arm over a port, an emulator
of its controller and the driver contract on the bus (docs/katana.md, "The serial protocol")."""
