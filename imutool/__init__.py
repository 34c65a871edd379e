"""imutool: marine inertial sensors from the deck to the certificate.

Library use needs no click: ``from imutool.attitude import ...``, ``from formats import read``.
"""

__version__ = "0.1.0"
