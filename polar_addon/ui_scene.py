"""Panels for the Blender settings Polar reads the way Cycles does but that Blender only shows for
Cycles or EEVEE: Film ▸ Transparent, the equirectangular panorama's ranges, Object ▸ Visibility (ray
visibility and holdout) and Cycles' Light Paths (bounces per kind, clamping, caustics).  They edit Blender's
own properties, so a file keeps the same settings in Cycles and Polar."""

import bpy


class _PolarPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    COMPAT_ENGINES = {"POLAR"}


class POLAR_PT_film(_PolarPanel, bpy.types.Panel):
    bl_label = "Film"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(context.scene.render, "film_transparent", text="Transparent")


class POLAR_PT_camera_panorama(_PolarPanel, bpy.types.Panel):
    bl_label = "Panorama"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and context.camera is not None and context.camera.type == "PANO"

    def draw(self, context):
        cam = context.camera
        layout = self.layout
        layout.use_property_split = True
        layout.prop(cam, "panorama_type")
        if cam.panorama_type == "EQUIRECTANGULAR":
            col = layout.column(align=True)
            col.prop(cam, "latitude_min", text="Latitude Min")
            col.prop(cam, "latitude_max", text="Max")
            col = layout.column(align=True)
            col.prop(cam, "longitude_min", text="Longitude Min")
            col.prop(cam, "longitude_max", text="Max")
        else:
            layout.label(text="Polar renders this panorama type as perspective", icon="ERROR")


class POLAR_PT_object_visibility(_PolarPanel, bpy.types.Panel):
    bl_label = "Polar Visibility"
    bl_context = "object"
    bl_options = {"DEFAULT_CLOSED"}
    GEOMETRY = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD"}

    @classmethod
    def poll(cls, context):
        ob = context.object
        return context.engine in cls.COMPAT_ENGINES and ob is not None and ob.type in cls.GEOMETRY

    def draw(self, context):
        ob = context.object
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(heading="Ray Visibility")
        for name, text in (("visible_camera", "Camera"), ("visible_diffuse", "Diffuse"), ("visible_glossy", "Glossy"),
                           ("visible_transmission", "Transmission"), ("visible_shadow", "Shadow")):
            col.prop(ob, name, text=text, toggle=False)
        layout.separator()
        layout.prop(ob, "is_holdout", text="Holdout")


class POLAR_PT_light_paths(_PolarPanel, bpy.types.Panel):
    """Cycles' Light Paths, which Polar reads (render_engine.cycles_light_paths): the same properties."""
    bl_label = "Light Paths"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context.scene, "cycles", None) is not None

    def draw(self, context):
        c = context.scene.cycles
        layout = self.layout
        layout.use_property_split = True
        col = layout.column(align=True, heading="Max Bounces")
        col.prop(c, "max_bounces", text="Total (caps Sampling ▸ Max Bounces)")
        col.prop(c, "diffuse_bounces", text="Diffuse")
        col.prop(c, "glossy_bounces", text="Glossy")
        col.prop(c, "transmission_bounces", text="Transmission")
        col.prop(c, "transparent_max_bounces", text="Transparent")
        col = layout.column(align=True, heading="Clamping")
        col.prop(c, "sample_clamp_direct", text="Direct Light")
        col.prop(c, "sample_clamp_indirect", text="Indirect Light")
        col = layout.column(align=True, heading="Caustics")
        col.prop(c, "blur_glossy", text="Filter Glossy")
        if c.blur_glossy > 0:
            col.label(text="Polar does not apply Filter Glossy", icon="ERROR")
        col.prop(c, "caustics_reflective", text="Reflective")
        col.prop(c, "caustics_refractive", text="Refractive")


classes = (POLAR_PT_film, POLAR_PT_camera_panorama, POLAR_PT_object_visibility, POLAR_PT_light_paths)

register, unregister = bpy.utils.register_classes_factory(classes)
