// skyfix console: the sky map of /ui/live (d3-celestial, canvas): bright stars, constellation lines, and the
// camera's footprint (its image outline projected on the sky), centred on the boresight.
"use strict";

const SkyMap = (() => {
  let outline = null; // GeoJSON LineString, [lon, lat] in degrees (lon = RA, -180..180)
  const lon = (ra) => (ra > 180 ? ra - 360 : ra);

  function init(containerId, width) {
    Celestial.add({
      type: "line",
      callback: () => {},
      redraw: () => {
        if (!outline) return;
        Celestial.setStyle({ stroke: "#facc15", width: 2.5, opacity: 1 });
        Celestial.context.beginPath();
        Celestial.map(outline);
        Celestial.context.stroke();
      },
    });
    Celestial.display({
      container: containerId, width, projection: "stereographic", transform: "equatorial",
      center: [0, 0, 0], zoomlevel: 4, zoomextend: 20, adaptable: true, interactive: true, // (false sets an inline style attribute, which the CSP refuses) form: false,
      controls: false, location: false, disableAnimations: true, datapath: "/ui/static/vendor/d3-celestial/data/",
      stars: { show: true, limit: 6, colors: true, names: false, proper: false, desig: false, size: 6, data: "stars.6.json" },
      dsos: { show: false, names: false }, mw: { show: false }, planets: { show: false },
      constellations: { names: true, namesType: "iau", lines: true, bounds: false,
        nameStyle: { fill: "#94a3b8", font: ["12px sans-serif", "11px sans-serif", "10px sans-serif"] } },
      lines: { graticule: { show: true, stroke: "#1e3a5f", width: 0.6, opacity: 0.8 },
        equatorial: { show: false }, ecliptic: { show: false }, galactic: { show: false }, supergalactic: { show: false } },
      background: { fill: "#000814", stroke: "#334155", opacity: 1, width: 1 },
    });
  }

  // points: [[ra, dec], ...] (deg) of the closed image outline; (ra, dec): the boresight
  function show(points, ra, dec) {
    outline = { type: "LineString", coordinates: points.map(([r, d]) => [lon(r), d]) };
    Celestial.rotate({ center: [lon(ra), dec, 0] });
  }

  return { init, show };
})();
