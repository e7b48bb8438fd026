"""Gymnasium environments for bucket loading on the FEE force simulator."""
