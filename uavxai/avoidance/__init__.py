"""avoidance"""
