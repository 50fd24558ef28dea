"""The spacecraft's CAN devices on the truth models (the nodes, their compiled kernels) and bus fault injection."""
