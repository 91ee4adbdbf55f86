//! The scene reader must return a scene or a typed error for any text, and a scene it
//! accepts must survive a TOML round trip.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(scene) = weft_sim::AnyScene::from_toml(&text) {
        let again = weft_sim::AnyScene::from_toml(&scene.to_toml().expect("serialises")).expect("re-reads");
        assert_eq!(again, scene);
    }
});
