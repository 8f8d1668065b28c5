"""ChefBot firmware from Python: the host build of the board (``FirmwareHost``)
and the shared protocol test vectors (``protocol_vectors``).

Keep this file free of path computations: catkin's devel space runs it via a
generated forwarding ``__init__`` whose ``__file__`` is not this one.
"""
from chefbot_firmware.host import FirmwareHost, FirmwareLibraryMissing, MotorOutput, library_path
from chefbot_firmware.protocol_vectors import load_vectors, vectors_path

__all__ = ["FirmwareHost", "FirmwareLibraryMissing", "MotorOutput", "library_path", "load_vectors",
           "vectors_path"]
