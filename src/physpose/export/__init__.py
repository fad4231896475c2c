"""Exports of a result folder: BVH, glTF binary, CSV and JSON joint tables."""
