"""keepout.fsw: the flight software (executive, modes, estimation, control, FDIR, TM/TC, bus driver).

Flight code never imports ``hil_sim``: everything it learns about the world comes through the bus
or through telecommands.
"""

import gnc  # noqa: F401,E402  first: arms the kernel cache locator (gnc/_after_numba.py)
