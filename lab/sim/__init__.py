"""lab.sim"""
