within ;
package Duffid "Duffing-type oscillator plants of duffid: translational mechanics, circuits, examples"
  annotation (
    version = "0.1.0",
    Documentation(info = "<html>
<p>Plant models of the <code>duffid</code> Python package (online identification of
Duffing-type oscillators). The library is self-contained (it needs no Modelica Standard
Library) and uses only continuous equations, so that <code>duffid.modelica.export.export_fmu</code>
can translate every example to an FMU; it opens unchanged in OpenModelica or Dymola.</p>
<ul>
<li><code>Units</code>: SI types with units and quantities.</li>
<li><code>Translational</code>: flange connector, fixed point, mass, springs (linear,
polynomial, cubic), damper, smooth Coulomb friction, force source.</li>
<li><code>Electrical</code>: pin, ground, resistor, inductor, capacitor, cubic capacitor,
saturating inductor, voltage source.</li>
<li><code>Examples</code>: the plants exported as FMUs.</li>
</ul>
</html>"));
end Duffid;
