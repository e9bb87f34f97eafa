def register_draaw_bsdf():
    pass
