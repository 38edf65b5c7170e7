"""lab.vision"""
