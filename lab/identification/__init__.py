"""lab.identification"""
