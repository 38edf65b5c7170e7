"""lab.search"""
