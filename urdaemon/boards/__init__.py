"""Servo boards as their datasheets and manuals define them, with no I/O: the PCA9685's registers
(``pca9685``) and the SSC-32 serial command lines (``ssc32``). The servo backend's links
(backends/servo/) put what these compute on a bus; the cell file checks its numbers against them."""
