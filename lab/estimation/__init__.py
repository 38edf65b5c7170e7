"""lab.estimation"""
