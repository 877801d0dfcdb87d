"""What the scanner outputs for a document: scan kernels, sensor, height maps, the scan
simulation, test charts, image measurements (RMTF, SFR) and OCR."""
