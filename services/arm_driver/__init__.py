"""The ASIBOT arm on CANopen: a CiA 402 master over python-can, and a 5-drive emulator.

Robot id `asibot`, service name `arm_driver`. Facts: /work/shared/reference/asibot.md section 4.
"""
