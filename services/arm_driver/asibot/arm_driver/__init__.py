"""The ASIBOT arm on CANopen: a CiA 402 master over python-can, and a 5-drive emulator
(the `emulator` package).

Robot id `asibot`, service name `arm_driver`. Facts and their sources: docs/canopen.md.
"""
