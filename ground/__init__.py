"""keepout's ground segment: monitor, archive, commanding and displays.

Not flight software: it reads the flight dictionary and telemetry codec from ``fsw`` (as F Prime's GDS
reads the flight dictionary) and never imports ``hil_sim``. ``fsw`` never imports ``ground``.
"""
