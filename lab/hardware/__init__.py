"""lab.hardware"""
