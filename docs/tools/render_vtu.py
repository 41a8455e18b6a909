"""Renders one time point of a `glissade run --vtu` series with VTK's offscreen renderer (the
VTK wheel: pip install vtk): the subdomains warped by their displacement (amplified to 5 % of the
model's size) and coloured by von Mises stress over its 2nd-98th percentiles, with a colour bar.

    python3 docs/tools/render_vtu.py <stem>-vtu/solid-NNNN.vtu out.png "title"
"""
import sys, vtk
solid_file, out = sys.argv[1:3]
def read(f):
    r = vtk.vtkXMLUnstructuredGridReader(); r.SetFileName(f); r.Update(); return r.GetOutput()
solid = read(solid_file)
solid.GetPointData().SetActiveVectors("displacement")
umax = solid.GetPointData().GetArray("displacement").GetMaxNorm()
b = solid.GetBounds(); diag = ((b[1]-b[0])**2 + (b[3]-b[2])**2) ** 0.5
scale = 0.05 * diag / umax
warp = vtk.vtkWarpVector(); warp.SetInputData(solid); warp.SetScaleFactor(scale)
geo = vtk.vtkDataSetSurfaceFilter(); geo.SetInputConnection(warp.GetOutputPort()); geo.SetNonlinearSubdivisionLevel(2)
vm = solid.GetPointData().GetArray("von_mises")
vals = sorted(vm.GetValue(i) for i in range(vm.GetNumberOfTuples()))
lo, hi = vals[int(0.02*len(vals))], vals[int(0.98*len(vals))]
m = vtk.vtkDataSetMapper(); m.SetInputConnection(geo.GetOutputPort()); m.SetScalarModeToUsePointFieldData(); m.SelectColorArray("von_mises"); m.SetScalarRange(lo, hi)
lut = vtk.vtkLookupTable(); lut.SetHueRange(0.667, 0.0); lut.Build(); m.SetLookupTable(lut)
a = vtk.vtkActor(); a.SetMapper(m)
bar = vtk.vtkScalarBarActor(); bar.SetLookupTable(lut); bar.SetTitle("von Mises (MPa)"); bar.SetNumberOfLabels(5); bar.SetOrientationToHorizontal()
bar.SetPosition(0.2, 0.03); bar.SetWidth(0.6); bar.SetHeight(0.12)
for p in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()): p.SetColor(0,0,0); p.ShadowOff(); p.ItalicOff()
ren = vtk.vtkRenderer(); ren.SetBackground(1,1,1); ren.AddActor(a); ren.AddViewProp(bar)
title = vtk.vtkTextActor(); title.SetInput((sys.argv[3] if len(sys.argv) > 3 else "") + f"  (displacements x {scale:.0f}; colour range: 2nd-98th percentile)"); title.GetTextProperty().SetColor(0,0,0); title.GetTextProperty().SetFontSize(18); title.SetPosition(10, 570)
ren.AddViewProp(title)
win = vtk.vtkRenderWindow(); win.SetOffScreenRendering(1); win.AddRenderer(ren); win.SetSize(1200, 600)
ren.ResetCamera(); cam = ren.GetActiveCamera(); cam.ParallelProjectionOn(); ren.ResetCamera(); cam.Zoom(1.15)
win.Render()
w2i = vtk.vtkWindowToImageFilter(); w2i.SetInput(win); w2i.Update()
png = vtk.vtkPNGWriter(); png.SetFileName(out); png.SetInputConnection(w2i.GetOutputPort()); png.Write()
print("range", lo, hi, "scale", scale)
